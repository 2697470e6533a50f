//! Changes to the fleet between ticks: each checked and all-or-nothing ([`edit`]), with the record
//! that takes it back ([`undo`]).

pub(crate) mod edit;
pub(crate) mod undo;
