//! The region network's certificates (`airroads certs`): a deployment's own certificate authority
//! and one certificate per region server, whose common name is the region's name. Zenoh's TLS
//! transport checks both ends against the CA (mutual TLS), and its access control lets a
//! certificate act only under its own region's keys (`region::secure`).
//!
//! Files in the output directory: `ca.pem` and `ca.key` (the authority; keep `ca.key` off the
//! servers), and `NAME.ROLE.pem` / `NAME.ROLE.key` per region and role. An existing authority is
//! reused and existing certificates are kept, so the command can add a region or a role later.

use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer, KeyPair,
    KeyUsagePurpose,
};
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// The authority's certificate file in a certificate directory.
pub const CA_CERT: &str = "ca.pem";
/// The authority's private key file in a certificate directory.
pub const CA_KEY: &str = "ca.key";
/// The authority's common name.
const CA_NAME: &str = "airroads region CA";
/// How long the authority is valid (days).
const CA_DAYS: u64 = 3650;

/// Why certificates could not be made.
#[derive(Debug, thiserror::Error)]
pub enum CertError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The reason.
        source: std::io::Error,
    },
    /// A key or certificate could not be made or read.
    #[error("{what}: {source}")]
    Crypto {
        /// What was being made or read.
        what: String,
        /// The reason.
        source: rcgen::Error,
    },
    /// An argument is not acceptable.
    #[error("{0}")]
    Invalid(String),
}

/// What to issue.
#[derive(Debug, Clone)]
pub struct Request {
    /// The region names (each becomes a certificate's common name).
    pub regions: Vec<String>,
    /// The roles per region (each a certificate `NAME.ROLE.pem`), e.g. `primary`, `standby`.
    pub roles: Vec<String>,
    /// Extra host names or IP addresses the certificates name (besides localhost, 127.0.0.1, ::1).
    pub hosts: Vec<String>,
    /// How long each server certificate is valid (days).
    pub days: u64,
}

/// One file the command wrote or kept.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Outcome {
    /// The certificate file.
    pub path: PathBuf,
    /// True when made now, false when it existed and was kept.
    pub made: bool,
}

/// A server's certificate files in `dir` for `region` and `role`: (certificate, key).
pub fn server_files(dir: &Path, region: &str, role: &str) -> (PathBuf, PathBuf) {
    (dir.join(format!("{region}.{role}.pem")), dir.join(format!("{region}.{role}.key")))
}

/// A name usable in a file name and a Zenoh key chunk: 1 to 64 of `A-Z a-z 0-9 _ -`.
fn check_name(kind: &str, name: &str) -> Result<(), CertError> {
    let ok = (1..=64).contains(&name.len())
        && name.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-');
    if ok {
        Ok(())
    } else {
        Err(CertError::Invalid(format!("{kind} `{name}`: expected 1 to 64 characters from A-Z a-z 0-9 _ -")))
    }
}

fn crypto(what: impl Into<String>) -> impl FnOnce(rcgen::Error) -> CertError {
    let what = what.into();
    move |source| CertError::Crypto { what, source }
}

fn read(path: &Path) -> Result<String, CertError> {
    std::fs::read_to_string(path).map_err(|source| CertError::Io { path: path.into(), source })
}

/// Writes `text` to a new file (never over an existing one); `secret` files are readable by the
/// owner only.
fn write_new(path: &Path, text: &str, secret: bool) -> Result<(), CertError> {
    use std::io::Write as _;
    let io = |source| CertError::Io { path: path.into(), source };
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt as _;
        options.mode(if secret { 0o600 } else { 0o644 });
    }
    let mut file = options.open(path).map_err(io)?;
    file.write_all(text.as_bytes()).map_err(io)?;
    file.sync_all().map_err(io)
}

/// Validity from now for `days`.
fn validity(params: &mut CertificateParams, days: u64) {
    let now = SystemTime::now().duration_since(UNIX_EPOCH).unwrap_or_default();
    // An hour back, for clocks of the deployment's machines that are slightly behind.
    let from = now.saturating_sub(Duration::from_secs(3600));
    let until = now + Duration::from_secs(days * 86_400);
    let at = |d: Duration| {
        let secs = i64::try_from(d.as_secs()).unwrap_or(i64::MAX);
        time::OffsetDateTime::from_unix_timestamp(secs).unwrap_or(time::OffsetDateTime::UNIX_EPOCH)
    };
    params.not_before = at(from);
    params.not_after = at(until);
}

/// The authority's parameters (the same every time, so an existing key signs as the same issuer).
fn ca_params() -> CertificateParams {
    let mut params = CertificateParams::default();
    params.distinguished_name = rcgen::DistinguishedName::new();
    params.distinguished_name.push(DnType::CommonName, CA_NAME);
    params.distinguished_name.push(DnType::OrganizationName, "airroads");
    params.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
    params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
    params
}

/// The authority of `dir`: read if `ca.key` exists, else made (and written).
fn authority(dir: &Path, made: &mut Vec<Outcome>) -> Result<Issuer<'static, KeyPair>, CertError> {
    let (cert_path, key_path) = (dir.join(CA_CERT), dir.join(CA_KEY));
    if key_path.exists() {
        let key = KeyPair::from_pem(&read(&key_path)?).map_err(crypto(key_path.display().to_string()))?;
        if !cert_path.exists() {
            return Err(CertError::Invalid(format!(
                "{} exists but {} does not; restore it or start a new directory",
                key_path.display(),
                cert_path.display()
            )));
        }
        made.push(Outcome { path: cert_path, made: false });
        return Ok(Issuer::new(ca_params(), key));
    }
    let key = KeyPair::generate().map_err(crypto("the authority's key"))?;
    let mut params = ca_params();
    validity(&mut params, CA_DAYS);
    let cert = params.self_signed(&key).map_err(crypto("the authority's certificate"))?;
    write_new(&cert_path, &cert.pem(), false)?;
    write_new(&key_path, &key.serialize_pem(), true)?;
    made.push(Outcome { path: cert_path, made: true });
    Ok(Issuer::new(ca_params(), key))
}

/// Issues the certificates of `request` into `dir` (created if missing); returns every
/// certificate file, made or kept, the authority first.
pub fn issue(dir: &Path, request: &Request) -> Result<Vec<Outcome>, CertError> {
    if request.regions.is_empty() || request.roles.is_empty() {
        return Err(CertError::Invalid("name at least one region and one role".into()));
    }
    for region in &request.regions {
        check_name("region", region)?;
    }
    for role in &request.roles {
        check_name("role", role)?;
    }
    if !(1..=3650).contains(&request.days) {
        return Err(CertError::Invalid(format!("--days {}: expected 1 to 3650", request.days)));
    }
    std::fs::create_dir_all(dir).map_err(|source| CertError::Io { path: dir.into(), source })?;
    let mut outcomes = Vec::new();
    let ca = authority(dir, &mut outcomes)?;
    let mut names = vec!["localhost".to_string(), "127.0.0.1".into(), "::1".into()];
    names.extend(request.hosts.iter().cloned());
    for region in &request.regions {
        for role in &request.roles {
            let (cert_path, key_path) = server_files(dir, region, role);
            if cert_path.exists() {
                outcomes.push(Outcome { path: cert_path, made: false });
                continue;
            }
            let mut params = CertificateParams::new(names.clone()).map_err(crypto("--host"))?;
            params.distinguished_name = rcgen::DistinguishedName::new();
            params.distinguished_name.push(DnType::CommonName, region.as_str());
            params.distinguished_name.push(DnType::OrganizationName, "airroads");
            params.distinguished_name.push(DnType::OrganizationalUnitName, role.as_str());
            params.key_usages = vec![KeyUsagePurpose::DigitalSignature];
            params.extended_key_usages =
                vec![ExtendedKeyUsagePurpose::ServerAuth, ExtendedKeyUsagePurpose::ClientAuth];
            params.use_authority_key_identifier_extension = true;
            validity(&mut params, request.days);
            let key = KeyPair::generate().map_err(crypto(format!("the key of {region}.{role}")))?;
            let cert =
                params.signed_by(&key, &ca).map_err(crypto(format!("the certificate of {region}.{role}")))?;
            // The key first: a certificate file without its key would be kept by a later run.
            write_new(&key_path, &key.serialize_pem(), true)?;
            write_new(&cert_path, &cert.pem(), false)?;
            outcomes.push(Outcome { path: cert_path, made: true });
        }
    }
    Ok(outcomes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(regions: &[&str]) -> Request {
        Request {
            regions: regions.iter().map(|s| s.to_string()).collect(),
            roles: vec!["primary".into(), "standby".into()],
            hosts: vec![],
            days: 30,
        }
    }

    #[test]
    fn issues_a_ca_and_one_certificate_per_region_and_role_then_keeps_them() {
        let dir = std::env::temp_dir().join(format!("airroads-certs-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let first = issue(&dir, &request(&["west", "east"])).unwrap();
        assert_eq!(first.len(), 5);
        assert!(first.iter().all(|o| o.made));
        let west = std::fs::read_to_string(dir.join("west.primary.pem")).unwrap();
        assert!(west.starts_with("-----BEGIN CERTIFICATE-----"));
        // A second run adds a region with the same authority and keeps the others.
        let second = issue(&dir, &request(&["west", "north"])).unwrap();
        let made: Vec<_> = second.iter().filter(|o| o.made).map(|o| o.path.clone()).collect();
        assert_eq!(made, vec![dir.join("north.primary.pem"), dir.join("north.standby.pem")]);
        assert_eq!(std::fs::read_to_string(dir.join("west.primary.pem")).unwrap(), west);
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt as _;
            let mode = std::fs::metadata(dir.join("west.primary.key")).unwrap().permissions().mode();
            assert_eq!(mode & 0o077, 0, "a private key is readable by others: {mode:o}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn names_that_cannot_be_a_key_chunk_are_refused() {
        let dir = std::env::temp_dir().join(format!("airroads-certs-bad-{}", std::process::id()));
        for bad in ["", "a/b", "a b", "*", &"x".repeat(65)] {
            let e = issue(&dir, &request(&[bad])).unwrap_err();
            assert!(e.to_string().contains("region"), "{bad:?}: {e}");
        }
        assert!(!dir.exists(), "nothing is written for a refused request");
    }
}
