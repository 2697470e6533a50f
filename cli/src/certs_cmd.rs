//! `airroads certs`: the region network's certificate authority and one certificate per region and
//! role (`regions::certs`).

use flights::say;

use crate::cli::CertsArgs;
use regions::certs;
use std::path::Path;
use std::process::ExitCode;

/// The region names of a scenario (`road.regions`) or road layout (`regions`) file.
fn regions_of(path: &Path) -> Result<Vec<String>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("--road {}: {e}", path.display()))?;
    let doc: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| format!("--road {}:{}: {e}", path.display(), e.line()))?;
    let road = doc.get("road").unwrap_or(&doc);
    let Some(regions) = road.get("regions").and_then(|r| r.as_array()) else {
        return Err(format!("--road {}: the road has no `regions`", path.display()));
    };
    regions
        .iter()
        .enumerate()
        .map(|(i, r)| {
            r.get("name")
                .and_then(|n| n.as_str())
                .map(str::to_string)
                .ok_or_else(|| format!("--road {}: regions[{i}].name: expected a string", path.display()))
        })
        .collect()
}

/// Runs `airroads certs`: exit 0 when every certificate exists, 2 for invalid input or a file
/// that cannot be written.
pub fn main(args: &CertsArgs) -> ExitCode {
    let mut regions = args.regions.clone();
    if let Some(road) = &args.road {
        match regions_of(road) {
            Ok(names) => regions.extend(names),
            Err(e) => {
                eprintln!("airroads certs: {e}");
                return ExitCode::from(2);
            }
        }
    }
    regions.dedup();
    if regions.is_empty() {
        eprintln!("airroads certs: name the regions with --region NAME or --road FILE.json");
        return ExitCode::from(2);
    }
    let request =
        certs::Request { regions, roles: args.roles.clone(), hosts: args.hosts.clone(), days: args.days };
    match certs::issue(&args.out, &request) {
        Ok(outcomes) => {
            for outcome in outcomes {
                let what = if outcome.made { "made" } else { "kept" };
                say!("{what}  {}", outcome.path.display());
            }
            say!(
                "keep {} off the servers; give each server ca.pem and its own NAME.ROLE.pem and .key",
                args.out.join(certs::CA_KEY).display()
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("airroads certs: {e}");
            ExitCode::from(2)
        }
    }
}
