//! The log port (5): TOC (channel 0), block control (channel 1) and periodic data (channel 2),
//! following the firmware's `log.c`.

use crate::crtp::{self, PORT_LOG, Packet};
pub use crate::logvars::LogVar;
use crate::logvars::{FLOAT, FP16, VARIABLES, type_len};
use crate::toc::{Toc, TocEntry};

const CONTROL_DELETE_BLOCK: u8 = 2;
const CONTROL_START_BLOCK: u8 = 3;
const CONTROL_STOP_BLOCK: u8 = 4;
const CONTROL_RESET: u8 = 5;
const CONTROL_CREATE_BLOCK_V2: u8 = 6;
const CONTROL_APPEND_BLOCK_V2: u8 = 7;
const CONTROL_START_BLOCK_V2: u8 = 8;

/// Errno values returned in control answers (newlib numbering, as on the Crazyflie).
const ENOENT: u8 = 2;
const E2BIG: u8 = 7;
const ENOEXEC: u8 = 8;
const ENOMEM: u8 = 12;
const EEXIST: u8 = 17;

/// Bytes of variable data in one log packet (block id and 3-byte timestamp take the rest).
const LOG_MAX_LEN: usize = 26;
const LOG_MAX_BLOCKS: usize = 16;
const LOG_MAX_OPS: usize = 128;

#[derive(Debug, Clone, Copy)]
struct Op {
    var: usize,
    storage: u8,
    log_type: u8,
}

#[derive(Debug, Clone)]
struct Block {
    id: u8,
    ops: Vec<Op>,
    /// Period in ms (0: one shot) and next due time in ms, while started.
    running: Option<(u32, f64)>,
}

impl Block {
    fn len(&self) -> usize {
        self.ops.iter().filter_map(|o| type_len(o.log_type)).sum()
    }
}

/// The log subsystem: TOC and blocks.
#[derive(Debug, Clone)]
pub struct Log {
    toc: Toc,
    blocks: Vec<Block>,
}

impl Default for Log {
    fn default() -> Self {
        Self::new()
    }
}

impl Log {
    /// The log subsystem with the simulator's TOC and no blocks.
    pub fn new() -> Self {
        let entries = VARIABLES
            .iter()
            .map(|&(group, name, type_byte, _)| TocEntry { group, name, type_byte })
            .collect();
        Self { toc: Toc::new(entries), blocks: Vec::new() }
    }

    /// The TOC.
    pub fn toc(&self) -> &Toc {
        &self.toc
    }

    /// Number of blocks currently defined.
    pub fn block_count(&self) -> usize {
        self.blocks.len()
    }

    /// Delete every block (the firmware does this on CONTROL_RESET and on link loss).
    pub fn reset(&mut self) {
        self.blocks.clear();
    }

    /// Handle a packet from the client on the log port at time `now_ms`.
    pub fn handle(&mut self, pk: &Packet, now_ms: f64) -> Option<Packet> {
        match pk.channel {
            0 => self.toc.handle(PORT_LOG, &pk.data, &[LOG_MAX_BLOCKS as u8, LOG_MAX_OPS as u8]),
            1 => self.control(&pk.data, now_ms),
            _ => None,
        }
    }

    fn control(&mut self, data: &[u8], now_ms: f64) -> Option<Packet> {
        let cmd = crtp::u8_at(data, 0)?;
        let id = crtp::u8_at(data, 1).unwrap_or(0);
        let settings = data.get(2..).unwrap_or(&[]);
        let ret = match cmd {
            CONTROL_DELETE_BLOCK => self.delete(id),
            CONTROL_START_BLOCK => {
                let period = u32::from(crtp::u8_at(data, 2).unwrap_or(0)) * 10;
                self.start(id, period, now_ms)
            }
            CONTROL_START_BLOCK_V2 => {
                let period = u32::from(crtp::u16_at(data, 2).unwrap_or(0));
                self.start(id, period, now_ms)
            }
            CONTROL_STOP_BLOCK => self.stop(id),
            CONTROL_RESET => {
                self.reset();
                0
            }
            CONTROL_CREATE_BLOCK_V2 => self.create(id, settings),
            CONTROL_APPEND_BLOCK_V2 => self.append(id, settings),
            _ => ENOEXEC,
        };
        Some(Packet::new(PORT_LOG, 1, vec![cmd, id, ret]))
    }

    fn create(&mut self, id: u8, settings: &[u8]) -> u8 {
        if self.blocks.iter().any(|b| b.id == id) {
            return EEXIST;
        }
        if self.blocks.len() >= LOG_MAX_BLOCKS {
            return ENOMEM;
        }
        self.blocks.push(Block { id, ops: Vec::new(), running: None });
        self.append(id, settings)
    }

    fn append(&mut self, id: u8, settings: &[u8]) -> u8 {
        let total_ops: usize = self.blocks.iter().map(|b| b.ops.len()).sum();
        let Some(block) = self.blocks.iter_mut().find(|b| b.id == id) else {
            return ENOENT;
        };
        for (k, s) in settings.chunks_exact(3).enumerate() {
            let log_type = s[0] & 0x0f;
            let var_id = u16::from_le_bytes([s[1], s[2]]);
            let Some(len) = type_len(log_type) else {
                return ENOENT;
            };
            if block.len() + len > LOG_MAX_LEN {
                return E2BIG;
            }
            if total_ops + k >= LOG_MAX_OPS {
                return ENOMEM;
            }
            // Raw memory addresses (id 0xffff) cannot be read in a simulator.
            let Some(&(_, _, storage, _)) = VARIABLES.get(usize::from(var_id)) else {
                return ENOENT;
            };
            block.ops.push(Op { var: usize::from(var_id), storage, log_type });
        }
        0
    }

    fn delete(&mut self, id: u8) -> u8 {
        let before = self.blocks.len();
        self.blocks.retain(|b| b.id != id);
        if self.blocks.len() == before { ENOENT } else { 0 }
    }

    fn start(&mut self, id: u8, period_ms: u32, now_ms: f64) -> u8 {
        let Some(block) = self.blocks.iter_mut().find(|b| b.id == id) else {
            return ENOENT;
        };
        // A timer fires one period after it is started; period 0 is a single immediate sample.
        block.running = Some((period_ms, now_ms + f64::from(period_ms)));
        0
    }

    fn stop(&mut self, id: u8) -> u8 {
        match self.blocks.iter_mut().find(|b| b.id == id) {
            Some(block) => {
                block.running = None;
                0
            }
            None => ENOENT,
        }
    }

    /// Data packets of the blocks due at `now_ms`, sampled with `sample`.
    pub fn due(&mut self, now_ms: f64, sample: impl Fn(LogVar) -> f64) -> Vec<Packet> {
        let mut out = Vec::new();
        for block in &mut self.blocks {
            let Some((period, due)) = block.running else { continue };
            if due > now_ms {
                continue;
            }
            // The firmware's timer fires on its own grid (start + n·period): a simulation step that
            // runs late samples at the last grid point it passed and skips the periods it missed
            // whole, so the timestamps stay on the grid however the host schedules this loop.
            let missed = if period == 0 { 0.0 } else { ((now_ms - due) / f64::from(period)).floor() };
            let fired = due + missed * f64::from(period);
            // Timestamp: milliseconds since boot, 24 bits.
            let ts = (fired.max(0.0) as u64 & 0x00ff_ffff) as u32;
            let mut data = vec![block.id];
            data.extend_from_slice(&ts.to_le_bytes()[..3]);
            for op in &block.ops {
                let value = VARIABLES.get(op.var).map_or(0.0, |v| sample(v.3));
                data.extend_from_slice(&encode(value, op.storage, op.log_type));
            }
            data.truncate(crtp::MAX_PAYLOAD);
            out.push(Packet::new(PORT_LOG, 2, data));
            block.running = if period == 0 {
                None
            } else {
                // The next grid point after this sample: missed periods are skipped, not burst.
                Some((period, fired + f64::from(period)))
            };
        }
        out
    }
}

/// Encode `value` held as `storage` type and sent as `log_type`, like `logRunBlock`.
fn encode(value: f64, storage: u8, log_type: u8) -> Vec<u8> {
    let (valuei, valuef) = if storage == FLOAT {
        let f = value as f32;
        (f as i32, f)
    } else {
        let i = value as i64 as i32;
        (i, i as f32)
    };
    match log_type {
        FLOAT => valuef.to_le_bytes().to_vec(),
        FP16 => f32_to_f16(valuef).to_le_bytes().to_vec(),
        t => {
            let len = type_len(t).unwrap_or(0);
            valuei.to_le_bytes()[..len].to_vec()
        }
    }
}

/// IEEE 754 binary16 bits of `v` (round toward zero, saturating to infinity).
fn f32_to_f16(v: f32) -> u16 {
    let bits = v.to_bits();
    let sign = ((bits >> 16) & 0x8000) as u16;
    let exp = ((bits >> 23) & 0xff) as i32;
    let mant = bits & 0x007f_ffff;
    if exp == 0xff {
        return sign | 0x7c00 | if mant != 0 { 0x200 } else { 0 };
    }
    let e = exp - 127 + 15;
    if e >= 0x1f {
        sign | 0x7c00
    } else if e <= 0 {
        if e < -10 {
            sign
        } else {
            let m = (mant | 0x0080_0000) >> (14 - e);
            sign | m as u16
        }
    } else {
        sign | ((e as u16) << 10) | (mant >> 13) as u16
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::logvars::{INT8, INT16, UINT16};

    fn control(log: &mut Log, data: &[u8]) -> Vec<u8> {
        log.handle(&Packet::new(PORT_LOG, 1, data.to_vec()), 0.0).expect("answer").data
    }

    #[test]
    fn block_lifecycle_and_data_layout() {
        let mut log = Log::new();
        assert_eq!(control(&mut log, &[6, 3, 7, 0, 0, 7, 2, 0]), vec![6, 3, 0]);
        assert_eq!(control(&mut log, &[6, 3]), vec![6, 3, EEXIST]);
        assert_eq!(control(&mut log, &[7, 3, 2, 14, 0]), vec![7, 3, 0]);
        assert_eq!(control(&mut log, &[3, 3, 1]), vec![3, 3, 0]);
        assert!(log.due(5.0, |_| 1.0).is_empty());
        let pk = log.due(10.0, |v| if v == LogVar::Z { 2.5 } else { 1.0 });
        assert_eq!(pk.len(), 1);
        let d = &pk[0].data;
        assert_eq!(d[..4], [3, 10, 0, 0]);
        assert_eq!(f32::from_le_bytes(d[4..8].try_into().expect("4")), 1.0);
        assert_eq!(f32::from_le_bytes(d[8..12].try_into().expect("4")), 2.5);
        assert_eq!(d[12..14], [1, 0]);
        assert!(log.due(15.0, |_| 0.0).is_empty());
        assert_eq!(log.due(20.0, |_| 0.0).len(), 1);
        assert_eq!(control(&mut log, &[4, 3]), vec![4, 3, 0]);
        assert!(log.due(100.0, |_| 0.0).is_empty());
        assert_eq!(control(&mut log, &[2, 3]), vec![2, 3, 0]);
        assert_eq!(control(&mut log, &[2, 3]), vec![2, 3, ENOENT]);
    }

    #[test]
    fn late_steps_keep_the_timestamps_on_the_grid() {
        let mut log = Log::new();
        control(&mut log, &[6, 3, 7, 0, 0]);
        control(&mut log, &[3, 3, 1]); // 10 ms, started at 0: due at 10, 20, 30, …
        let stamp = |pk: &[Packet]| u32::from_le_bytes([pk[0].data[1], pk[0].data[2], pk[0].data[3], 0]);
        // Two ms late: sampled for 10, the next one still due at 20 (no 12, 8 pair).
        assert_eq!(stamp(&log.due(12.0, |_| 0.0)), 10);
        assert!(log.due(19.5, |_| 0.0).is_empty());
        assert_eq!(stamp(&log.due(20.0, |_| 0.0)), 20);
        // A stall past 30 and 40: one sample for 40, then 50 (missed periods skipped, not burst).
        let pk = log.due(47.0, |_| 0.0);
        assert_eq!((pk.len(), stamp(&pk)), (1, 40));
        assert!(log.due(49.0, |_| 0.0).is_empty());
        assert_eq!(stamp(&log.due(50.5, |_| 0.0)), 50);
    }

    #[test]
    fn limits_and_errors() {
        let mut log = Log::new();
        // 7 floats = 28 bytes > 26.
        let mut create = vec![6, 1];
        for _ in 0..7 {
            create.extend_from_slice(&[7, 0, 0]);
        }
        assert_eq!(control(&mut log, &create), vec![6, 1, E2BIG]);
        assert_eq!(control(&mut log, &[6, 2, 7, 0xff, 0xff]), vec![6, 2, ENOENT]);
        assert_eq!(control(&mut log, &[7, 99, 7, 0, 0]), vec![7, 99, ENOENT]);
        assert_eq!(control(&mut log, &[3, 99, 1]), vec![3, 99, ENOENT]);
        assert_eq!(control(&mut log, &[42]), vec![42, 0, ENOEXEC]);
        assert_eq!(control(&mut log, &[5]), vec![5, 0, 0]);
        assert_eq!(log.block_count(), 0);
        for id in 0..16 {
            assert_eq!(control(&mut log, &[6, id]), vec![6, id, 0]);
        }
        assert_eq!(control(&mut log, &[6, 200]), vec![6, 200, ENOMEM]);
        assert!(log.handle(&Packet::new(PORT_LOG, 1, vec![]), 0.0).is_none());
        assert!(log.handle(&Packet::new(PORT_LOG, 2, vec![1, 2]), 0.0).is_none());
    }

    #[test]
    fn conversions() {
        assert_eq!(encode(1.75, FLOAT, INT16), vec![1, 0]);
        assert_eq!(encode(-1.0, FLOAT, INT8), vec![0xff]);
        assert_eq!(encode(3.0, UINT16, FLOAT), 3.0f32.to_le_bytes().to_vec());
        assert_eq!(f32_to_f16(1.0), 0x3c00);
        assert_eq!(f32_to_f16(-2.0), 0xc000);
        assert_eq!(f32_to_f16(1e9), 0x7c00);
        assert_eq!(f32_to_f16(0.0), 0);
    }
}
