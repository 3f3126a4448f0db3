//! BlueOS's autopilot manager asked for the daemon's own MAVLink endpoint
//! (`[mavlink] blueos_endpoint = true`, docs/blueos.md): as BlueOS
//! extensions do, the daemon adds an endpoint to the manager's MAVLink
//! router at start, so that nobody has to add it by hand in BlueOS's
//! interface, and then opens its link to it as configured.
//!
//! The endpoint is the other end of `[mavlink] connection`: for
//! `udpout:H:P` (the daemon sends to H:P) a "UDP Server" (`udpin`) on H:P;
//! for `udpin:A:P` (the daemon listens) a "UDP Client" (`udpout`) to A:P.
//! An endpoint already there (a restart, a reinstall) is left as it is.
//!
//! A small HTTP/1.1 client of its own (the daemon has no HTTP client to
//! share): two requests at start, each bounded by [`DEADLINE`].

use lightpose_vehicle::Endpoint;
use serde_json::{json, Value};
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// The most one request to the manager may take.
pub const DEADLINE: Duration = Duration::from_secs(3);
/// The most of an answer read.
const MAX_ANSWER: usize = 1 << 20;

/// Where the manager is and the endpoint to ask it for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BlueosEndpoint {
    /// `http://HOST[:PORT][/PREFIX]`, as configured (`blueos_url`).
    pub url: String,
    pub host: String,
    pub port: u16,
    /// The manager's path on that host (`/ardupilot-manager` behind
    /// BlueOS's web server), without a trailing `/`.
    pub prefix: String,
    /// `udpin` or `udpout`, BlueOS's words.
    pub connection_type: &'static str,
    pub place: String,
    pub argument: u16,
}

/// The manager as BlueOS serves it on the vehicle (the extension runs with
/// host networking).
pub const DEFAULT_URL: &str = "http://127.0.0.1/ardupilot-manager";

impl BlueosEndpoint {
    /// The endpoint that is the other end of `link`, at the manager at
    /// `url`; why not, in words, for a link that is not UDP or a URL that
    /// is not `http://`.
    pub fn new(url: &str, link: &Endpoint) -> Result<BlueosEndpoint, String> {
        let (connection_type, place, argument) = match link {
            Endpoint::UdpOut { host, port } => ("udpin", host.clone(), *port),
            Endpoint::UdpIn(a) => {
                // The router sends to this host: a wildcard listen is
                // reached on loopback.
                let ip = if a.ip().is_unspecified() { "127.0.0.1".to_string() } else { a.ip().to_string() };
                ("udpout", ip, a.port())
            }
            other => {
                return Err(format!(
                    "needs a UDP connection (udpout:HOST:PORT or udpin:ADDR:PORT) for BlueOS's router, not {other}"
                ))
            }
        };
        let rest = url.strip_prefix("http://").ok_or_else(|| {
            format!(
                "{url:?} is not an http:// address (the manager speaks plain HTTP on the vehicle)"
            )
        })?;
        let (authority, path) = rest.split_once('/').map_or((rest, ""), |(a, p)| (a, p));
        let (host, port) = match authority.rsplit_once(':') {
            Some((h, p)) if !h.ends_with(']') || authority.starts_with('[') => {
                let port = p
                    .parse::<u16>()
                    .map_err(|_| format!("{p:?} in {url:?} is not a port"))?;
                (
                    h.trim_start_matches('[').trim_end_matches(']').to_string(),
                    port,
                )
            }
            _ => (authority.to_string(), 80),
        };
        if host.is_empty() || port == 0 {
            return Err(format!("{url:?} names no host and port"));
        }
        let prefix = format!("/{}", path.trim_matches('/'));
        let prefix = if prefix == "/" { String::new() } else { prefix };
        Ok(BlueosEndpoint {
            url: url.to_string(),
            host,
            port,
            prefix,
            connection_type,
            place,
            argument,
        })
    }

    /// The endpoint as the manager's API takes it (one of the set POSTed).
    pub fn body(&self) -> Value {
        json!({
            "name": "lightpose",
            "owner": "lightpose",
            "connection_type": self.connection_type,
            "place": self.place,
            "argument": self.argument,
            "persistent": true,
            "protected": false,
            "enabled": true,
        })
    }

    fn path(&self) -> String {
        format!("{}/v1.0/endpoints/", self.prefix)
    }
}

#[derive(Debug, thiserror::Error)]
pub enum BlueosError {
    #[error("{0}: {1}")]
    Io(&'static str, std::io::Error),
    #[error("no answer within {0:?}")]
    Timeout(Duration),
    #[error("{0}")]
    Answer(String),
}

/// What became of the request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Asked {
    /// The manager added the endpoint.
    Created,
    /// It had it already.
    Present,
}

/// Ask the manager for `e`: look at its endpoints, add ours if absent.
pub async fn ask(e: &BlueosEndpoint) -> Result<Asked, BlueosError> {
    let (code, body) = request(e, "GET", None).await?;
    if code != 200 {
        return Err(BlueosError::Answer(format!(
            "GET {} answered {code}",
            e.path()
        )));
    }
    let list: Value = serde_json::from_slice(&body)
        .map_err(|err| BlueosError::Answer(format!("GET {}: not JSON: {err}", e.path())))?;
    let same = |v: &Value| {
        v["connection_type"] == e.connection_type
            && v["place"] == e.place.as_str()
            && v["argument"] == e.argument
    };
    if list.as_array().is_some_and(|l| l.iter().any(same)) {
        return Ok(Asked::Present);
    }
    let post = json!([e.body()]).to_string();
    let (code, body) = request(e, "POST", Some(&post)).await?;
    if !(200..300).contains(&code) {
        let why = lightpose_core::textfile::excerpt(&String::from_utf8_lossy(&body), 200);
        return Err(BlueosError::Answer(format!(
            "POST {} answered {code}: {why}",
            e.path()
        )));
    }
    Ok(Asked::Created)
}

/// One request; its status code and body.
async fn request(
    e: &BlueosEndpoint,
    method: &str,
    body: Option<&str>,
) -> Result<(u16, Vec<u8>), BlueosError> {
    let go = async {
        let mut s = tokio::net::TcpStream::connect((e.host.as_str(), e.port))
            .await
            .map_err(|err| BlueosError::Io("connect", err))?;
        let body = body.unwrap_or("");
        let head = format!(
            "{method} {} HTTP/1.1\r\nHost: {}\r\nAccept: application/json\r\nContent-Type: application/json\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
            e.path(),
            e.host,
            body.len()
        );
        s.write_all(head.as_bytes())
            .await
            .map_err(|err| BlueosError::Io("send", err))?;
        s.write_all(body.as_bytes())
            .await
            .map_err(|err| BlueosError::Io("send", err))?;
        let mut all = Vec::new();
        let mut buf = [0u8; 8192];
        loop {
            let n = s
                .read(&mut buf)
                .await
                .map_err(|err| BlueosError::Io("read", err))?;
            if n == 0 || all.len() + n > MAX_ANSWER {
                break;
            }
            all.extend_from_slice(&buf[..n]);
        }
        parse_answer(&all)
    };
    tokio::time::timeout(DEADLINE, go)
        .await
        .map_err(|_| BlueosError::Timeout(DEADLINE))?
}

/// The status code and body of an HTTP/1.1 answer (chunked or not).
fn parse_answer(all: &[u8]) -> Result<(u16, Vec<u8>), BlueosError> {
    let end = all
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .ok_or_else(|| BlueosError::Answer("an answer without a complete head".into()))?;
    let head = String::from_utf8_lossy(&all[..end]);
    let code = head
        .split(' ')
        .nth(1)
        .and_then(|c| c.parse::<u16>().ok())
        .ok_or_else(|| {
            BlueosError::Answer(format!(
                "not an HTTP answer: {}",
                lightpose_core::textfile::excerpt(&head, 80)
            ))
        })?;
    let body = &all[end + 4..];
    let chunked = head.lines().any(|l| {
        l.to_ascii_lowercase().starts_with("transfer-encoding:")
            && l.to_ascii_lowercase().contains("chunked")
    });
    Ok((
        code,
        if chunked {
            dechunk(body)
        } else {
            body.to_vec()
        },
    ))
}

/// A chunked body joined (what a truncated one holds so far).
fn dechunk(mut b: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    while let Some(i) = b.windows(2).position(|w| w == b"\r\n") {
        let size = std::str::from_utf8(&b[..i])
            .ok()
            .and_then(|s| usize::from_str_radix(s.split(';').next().unwrap_or("").trim(), 16).ok());
        let Some(size) = size.filter(|s| *s > 0) else {
            break;
        };
        let start = i + 2;
        let stop = (start + size).min(b.len());
        out.extend_from_slice(&b[start..stop]);
        b = b.get(stop + 2..).unwrap_or(&[]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_endpoint_is_the_other_end_of_the_link() {
        let out: Endpoint = "udpout:127.0.0.1:14660".parse().unwrap();
        let e = BlueosEndpoint::new(DEFAULT_URL, &out).unwrap();
        assert_eq!(
            (e.host.as_str(), e.port, e.prefix.as_str()),
            ("127.0.0.1", 80, "/ardupilot-manager")
        );
        assert_eq!(
            (e.connection_type, e.place.as_str(), e.argument),
            ("udpin", "127.0.0.1", 14660)
        );
        assert_eq!(e.path(), "/ardupilot-manager/v1.0/endpoints/");
        let inn: Endpoint = "udpin:0.0.0.0:14661".parse().unwrap();
        let e = BlueosEndpoint::new("http://192.168.2.2:8000", &inn).unwrap();
        assert_eq!(
            (e.host.as_str(), e.port, e.path()),
            ("192.168.2.2", 8000, "/v1.0/endpoints/".to_string())
        );
        assert_eq!(
            (e.connection_type, e.place.as_str()),
            ("udpout", "127.0.0.1")
        );
        let serial: Endpoint = "serial:/dev/ttyACM0:115200".parse().unwrap();
        assert!(BlueosEndpoint::new(DEFAULT_URL, &serial)
            .unwrap_err()
            .starts_with("needs a UDP connection"));
        assert!(BlueosEndpoint::new("https://x", &out)
            .unwrap_err()
            .contains("not an http://"));
        assert!(BlueosEndpoint::new("http://x:99999/", &out)
            .unwrap_err()
            .contains("is not a port"));
    }

    #[test]
    fn answers_are_read_plain_or_chunked() {
        let (c, b) =
            parse_answer(b"HTTP/1.1 201 Created\r\nContent-Length: 4\r\n\r\nnull").unwrap();
        assert_eq!((c, b.as_slice()), (201, b"null".as_slice()));
        let (c, b) = parse_answer(
            b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n2\r\n[]\r\n0\r\n\r\n",
        )
        .unwrap();
        assert_eq!((c, b.as_slice()), (200, b"[]".as_slice()));
        assert!(parse_answer(b"HTTP/1.1 200").is_err());
    }
}
