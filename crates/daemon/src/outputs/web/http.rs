//! A small HTTP/1.1 server for the page and its API, on the daemon's
//! runtime: one request a connection (`Connection: close`), GET and HEAD
//! only while `[web] control` is off. Hand-written rather than hyper: the
//! daemon serves a handful of fixed paths, and the binary runs on a Pi.
//!
//! Issue 44 found the Foxglove server's holes; none is left open here:
//! - a request head is at most [`Limits::head_bytes`] and must arrive
//!   within [`Limits::head_deadline`] (a client that sends slowly, or
//!   nothing, is closed: counted `timed_out`);
//! - at most `max_clients` connections at once, whatever they are doing
//!   (reading a head, streaming the feed), and at most `per_addr` from one
//!   address; the others get a 503 and are closed at once (`refused`);
//! - every write has [`Limits::write_deadline`]: a client that stops
//!   reading is cut (`not_reading`), and until then holds one event
//!   (the `watch` slot), never a queue.

use super::assets;
use super::control;
use super::WebFeed;
use bytes::Bytes;
use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering::Relaxed};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::watch;

/// What one connection may cost.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    pub max_clients: usize,
    pub per_addr: usize,
    pub head_bytes: usize,
    pub head_deadline: Duration,
    pub write_deadline: Duration,
    /// A comment line on a quiet feed, so that proxies keep it open and a
    /// dead peer shows.
    pub keepalive: Duration,
}

impl Limits {
    pub fn new(max_clients: usize, per_addr: usize) -> Limits {
        Limits {
            max_clients,
            per_addr,
            head_bytes: 8 << 10,
            head_deadline: Duration::from_secs(5),
            write_deadline: Duration::from_secs(5),
            keepalive: Duration::from_secs(10),
        }
    }
}

/// The server's counters (STATUS `web`).
#[derive(Default)]
pub struct Counters {
    /// Connections open now, and of them live feeds.
    pub open: AtomicUsize,
    pub live_open: AtomicUsize,
    pub accepted: AtomicU64,
    pub refused: AtomicU64,
    pub bad_requests: AtomicU64,
    pub timed_out: AtomicU64,
    pub not_reading: AtomicU64,
}

/// The places taken, per address: one lock, taken at accept and at close.
#[derive(Default)]
struct Places {
    total: usize,
    by_addr: HashMap<IpAddr, usize>,
}

/// A place held by one connection, given back when it ends however it
/// ends.
struct Place {
    places: Arc<Mutex<Places>>,
    host: IpAddr,
    feed: Arc<WebFeed>,
}

impl Drop for Place {
    fn drop(&mut self) {
        if let Ok(mut p) = self.places.lock() {
            p.total = p.total.saturating_sub(1);
            if let Some(n) = p.by_addr.get_mut(&self.host) {
                *n -= 1;
                if *n == 0 {
                    p.by_addr.remove(&self.host);
                }
            }
        }
        self.feed.counters.open.fetch_sub(1, Relaxed);
    }
}

/// A place for a connection from `host`, if one is free to it.
fn take_place(
    places: &Arc<Mutex<Places>>,
    host: IpAddr,
    limits: &Limits,
    feed: &Arc<WebFeed>,
) -> Option<Place> {
    let mut p = places.lock().ok()?;
    let mine = p.by_addr.get(&host).copied().unwrap_or(0);
    if p.total >= limits.max_clients || mine >= limits.per_addr {
        return None;
    }
    p.total += 1;
    *p.by_addr.entry(host).or_insert(0) += 1;
    feed.counters.open.fetch_add(1, Relaxed);
    Some(Place {
        places: places.clone(),
        host,
        feed: feed.clone(),
    })
}

/// Accept connections until the daemon stops.
pub async fn serve(listener: TcpListener, feed: Arc<WebFeed>, limits: Limits) {
    let places = Arc::new(Mutex::new(Places::default()));
    let mut closing = feed.closing();
    loop {
        let accepted = tokio::select! {
            a = listener.accept() => a,
            _ = closing.changed() => return,
        };
        let (stream, addr) = match accepted {
            Ok(a) => a,
            Err(e) => {
                // Out of descriptors, most likely: wait rather than spin.
                tracing::warn!("web: accept failed: {e}");
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        if feed.is_closed() {
            return;
        }
        feed.counters.accepted.fetch_add(1, Relaxed);
        let host = addr.ip().to_canonical();
        match take_place(&places, host, &limits, &feed) {
            Some(place) => {
                let f = feed.clone();
                tokio::spawn(async move {
                    connection(stream, addr, &f, &limits).await;
                    drop(place);
                });
            }
            None => {
                feed.counters.refused.fetch_add(1, Relaxed);
                tokio::spawn(refuse(stream, limits.write_deadline));
            }
        }
    }
}

/// Every place taken (or this address's share): a 503, at once.
async fn refuse(mut stream: TcpStream, deadline: Duration) {
    let body = br#"{"error":"too many connections to the lightpose page: close another tab or try again"}"#;
    let head = head(
        503,
        "Service Unavailable",
        "application/json",
        body.len(),
        "Retry-After: 2\r\n",
    );
    let _ = tokio::time::timeout(deadline, async {
        stream.write_all(head.as_bytes()).await?;
        stream.write_all(body).await?;
        stream.shutdown().await
    })
    .await;
}

fn head(code: u16, reason: &str, ctype: &str, len: usize, extra: &str) -> String {
    format!(
        "HTTP/1.1 {code} {reason}\r\nContent-Type: {ctype}\r\nContent-Length: {len}\r\nCache-Control: no-store\r\nX-Content-Type-Options: nosniff\r\nConnection: close\r\n{extra}\r\n"
    )
}

/// A request as far as this server reads one.
#[derive(Debug, PartialEq, Eq)]
pub struct Request {
    pub method: String,
    /// Without its query.
    pub path: String,
    /// The body's length, when the head says it.
    pub content_length: Option<usize>,
}

/// Why a request head was refused.
#[derive(Debug, PartialEq, Eq)]
pub enum HeadError {
    TooLarge,
    Malformed(&'static str),
    Closed,
}

/// The request line of a complete head (`\r\n\r\n` seen).
pub fn parse_head(head: &[u8]) -> Result<Request, HeadError> {
    let text = std::str::from_utf8(head).map_err(|_| HeadError::Malformed("not UTF-8"))?;
    let line = text.lines().next().unwrap_or("");
    let mut parts = line.split(' ');
    let (Some(method), Some(target), Some(version), None) =
        (parts.next(), parts.next(), parts.next(), parts.next())
    else {
        return Err(HeadError::Malformed(
            "request line is not METHOD TARGET VERSION",
        ));
    };
    if !version.starts_with("HTTP/1.") {
        return Err(HeadError::Malformed("not HTTP/1.x"));
    }
    if method.is_empty() || !method.bytes().all(|b| b.is_ascii_uppercase()) {
        return Err(HeadError::Malformed("bad method"));
    }
    let path = target.split(['?', '#']).next().unwrap_or("");
    if !path.starts_with('/') {
        return Err(HeadError::Malformed("target is not a path"));
    }
    let mut content_length = None;
    for h in text.lines().skip(1) {
        let Some((name, value)) = h.split_once(':') else {
            continue;
        };
        if name.trim().eq_ignore_ascii_case("content-length") {
            let n = value
                .trim()
                .parse::<usize>()
                .map_err(|_| HeadError::Malformed("bad Content-Length"))?;
            content_length = Some(n);
        }
    }
    Ok(Request {
        method: method.to_string(),
        path: path.to_string(),
        content_length,
    })
}

/// Read until the end of the head, at most `max` bytes: what was read,
/// and where the head ends in it (a body may follow).
async fn read_head(stream: &mut TcpStream, max: usize) -> Result<(Vec<u8>, usize), HeadError> {
    let mut buf = vec![0u8; max];
    let mut n = 0;
    loop {
        if n == max {
            return Err(HeadError::TooLarge);
        }
        let got = stream
            .read(&mut buf[n..])
            .await
            .map_err(|_| HeadError::Closed)?;
        if got == 0 {
            return Err(HeadError::Closed);
        }
        // The end may straddle two reads: look from 3 bytes back.
        let from = n.saturating_sub(3);
        n += got;
        if let Some(end) = buf[from..n].windows(4).position(|w| w == b"\r\n\r\n") {
            buf.truncate(n);
            return Ok((buf, from + end + 4));
        }
    }
}

/// One connection: its request, answered.
async fn connection(mut stream: TcpStream, addr: SocketAddr, feed: &Arc<WebFeed>, limits: &Limits) {
    let _ = stream.set_nodelay(true);
    let got = tokio::time::timeout(
        limits.head_deadline,
        read_head(&mut stream, limits.head_bytes),
    )
    .await;
    let (req, rest) = match got {
        Err(_) => {
            feed.counters.timed_out.fetch_add(1, Relaxed);
            return;
        }
        Ok(Err(HeadError::Closed)) => return,
        Ok(Err(e)) => {
            feed.counters.bad_requests.fetch_add(1, Relaxed);
            let (code, reason, msg) = match e {
                HeadError::TooLarge => (
                    431,
                    "Request Header Fields Too Large",
                    "request head over 8 KiB".to_string(),
                ),
                HeadError::Malformed(why) => (400, "Bad Request", format!("bad request: {why}")),
                HeadError::Closed => return,
            };
            let _ = send_error(&mut stream, code, reason, &msg, limits).await;
            return;
        }
        Ok(Ok((h, end))) => match parse_head(&h[..end]) {
            Ok(r) => (r, h[end..].to_vec()),
            Err(HeadError::Malformed(why)) => {
                feed.counters.bad_requests.fetch_add(1, Relaxed);
                let _ = send_error(
                    &mut stream,
                    400,
                    "Bad Request",
                    &format!("bad request: {why}"),
                    limits,
                )
                .await;
                return;
            }
            Err(_) => return,
        },
    };
    let r = if control::is_control(&req) {
        control::answer(&mut stream, &req, &rest, feed, limits).await
    } else {
        answer(&mut stream, &req, feed, limits).await
    };
    if let Err(Cut::NotReading) = r {
        feed.counters.not_reading.fetch_add(1, Relaxed);
        tracing::debug!("web: {addr} stopped reading: cut");
    }
}

/// Why a connection ended early.
pub enum Cut {
    NotReading,
    Gone,
}

pub async fn write(stream: &mut TcpStream, bytes: &[u8], limits: &Limits) -> Result<(), Cut> {
    match tokio::time::timeout(limits.write_deadline, stream.write_all(bytes)).await {
        Ok(Ok(())) => Ok(()),
        Ok(Err(_)) => Err(Cut::Gone),
        Err(_) => Err(Cut::NotReading),
    }
}

pub async fn send(
    stream: &mut TcpStream,
    code: u16,
    reason: &str,
    ctype: &str,
    body: &[u8],
    with_body: bool,
    limits: &Limits,
) -> Result<(), Cut> {
    let h = head(code, reason, ctype, body.len(), "");
    write(stream, h.as_bytes(), limits).await?;
    if with_body {
        write(stream, body, limits).await?;
    }
    let _ = stream.shutdown().await;
    Ok(())
}

pub async fn send_error(
    stream: &mut TcpStream,
    code: u16,
    reason: &str,
    msg: &str,
    limits: &Limits,
) -> Result<(), Cut> {
    let body = serde_json::json!({ "error": msg }).to_string();
    send(
        stream,
        code,
        reason,
        "application/json",
        body.as_bytes(),
        true,
        limits,
    )
    .await
}

/// The answer to `req`.
async fn answer(
    stream: &mut TcpStream,
    req: &Request,
    feed: &Arc<WebFeed>,
    limits: &Limits,
) -> Result<(), Cut> {
    let body = match req.method.as_str() {
        "GET" => true,
        "HEAD" => false,
        _ => {
            let msg = if feed.control {
                format!("{} {}: not a request this page takes", req.method, req.path)
            } else {
                format!(
                    "{} {}: the page is read-only ([web] control = false)",
                    req.method, req.path
                )
            };
            return send_error(stream, 405, "Method Not Allowed", &msg, limits).await;
        }
    };
    if req.path == "/v1/events" {
        if !body {
            return send(stream, 200, "OK", "text/event-stream", b"", false, limits).await;
        }
        return events(stream, feed, limits).await;
    }
    if let Some(a) = assets::find(&req.path) {
        return send(stream, 200, "OK", a.ctype, a.body, body, limits).await;
    }
    let json = "application/json";
    match req.path.as_str() {
        "/register_service" => {
            let b = assets::register_service();
            send(stream, 200, "OK", json, b.as_bytes(), body, limits).await
        }
        "/v1/status" => match nonempty(feed.latest_status()) {
            Some(s) => send(stream, 200, "OK", json, &s, body, limits).await,
            None => {
                send_error(
                    stream,
                    503,
                    "Service Unavailable",
                    "no STATUS yet: the daemon is starting",
                    limits,
                )
                .await
            }
        },
        "/v1/pose" => match nonempty(feed.latest_pose()) {
            Some(p) => send(stream, 200, "OK", json, &p, body, limits).await,
            None => {
                send_error(
                    stream,
                    503,
                    "Service Unavailable",
                    "no POSE yet: no frame estimated so far",
                    limits,
                )
                .await
            }
        },
        _ => {
            let msg = format!("{}: no such page", req.path);
            send_error(stream, 404, "Not Found", &msg, limits).await
        }
    }
}

fn nonempty(b: Bytes) -> Option<Bytes> {
    (!b.is_empty()).then_some(b)
}

/// The live feed (server-sent events): `live` events as the feed thread
/// makes them, `status` at each STATUS, a comment when quiet; until the
/// client goes, stops reading, or the daemon stops.
async fn events(stream: &mut TcpStream, feed: &Arc<WebFeed>, limits: &Limits) -> Result<(), Cut> {
    let h = "HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\nCache-Control: no-store\r\nX-Accel-Buffering: no\r\nConnection: close\r\n\r\nretry: 1000\n\n";
    write(stream, h.as_bytes(), limits).await?;
    feed.counters.live_open.fetch_add(1, Relaxed);
    let r = stream_events(stream, feed, limits).await;
    feed.counters.live_open.fetch_sub(1, Relaxed);
    r
}

async fn stream_events(
    stream: &mut TcpStream,
    feed: &Arc<WebFeed>,
    limits: &Limits,
) -> Result<(), Cut> {
    let (mut live, mut status) = feed.subscribe();
    let mut closing = feed.closing();
    // What is there already goes first: the page is not blank for a second.
    live.mark_changed();
    status.mark_changed();
    let mut buf: Vec<u8> = Vec::with_capacity(16 << 10);
    let mut peek = [0u8; 256];
    loop {
        buf.clear();
        tokio::select! {
            r = live.changed() => {
                if r.is_err() { return Ok(()) }
                sse(&mut buf, "live", &live.borrow_and_update());
            }
            r = status.changed() => {
                if r.is_err() { return Ok(()) }
                sse(&mut buf, "status", &status.borrow_and_update());
            }
            _ = closing.changed() => return Ok(()),
            // A browser sends nothing more: a read that ends is its close.
            r = stream.read(&mut peek) => match r {
                Ok(0) | Err(_) => return Err(Cut::Gone),
                Ok(_) => continue,
            },
            () = tokio::time::sleep(limits.keepalive) => buf.extend_from_slice(b": keepalive\n\n"),
        }
        if buf.is_empty() {
            continue;
        }
        write(stream, &buf, limits).await?;
    }
}

/// One server-sent event of JSON `data` (compact JSON has no newline).
fn sse(buf: &mut Vec<u8>, name: &str, data: &watch::Ref<'_, Bytes>) {
    if data.is_empty() {
        return;
    }
    buf.extend_from_slice(b"event: ");
    buf.extend_from_slice(name.as_bytes());
    buf.extend_from_slice(b"\ndata: ");
    buf.extend_from_slice(data);
    buf.extend_from_slice(b"\n\n");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_line_is_read_strictly() {
        let r = parse_head(b"GET /v1/pose?x=1 HTTP/1.1\r\nHost: a\r\n\r\n").unwrap();
        assert_eq!((r.method.as_str(), r.path.as_str()), ("GET", "/v1/pose"));
        let bad = |h: &[u8]| parse_head(h).unwrap_err();
        assert_eq!(
            bad(b"GET /\r\n\r\n"),
            HeadError::Malformed("request line is not METHOD TARGET VERSION")
        );
        assert_eq!(
            bad(b"GET / SPDY/3\r\n\r\n"),
            HeadError::Malformed("not HTTP/1.x")
        );
        assert_eq!(
            bad(b"get / HTTP/1.1\r\n\r\n"),
            HeadError::Malformed("bad method")
        );
        assert_eq!(
            bad(b"GET http://x/ HTTP/1.1\r\n\r\n"),
            HeadError::Malformed("target is not a path")
        );
        assert_eq!(
            bad(b"GET /\xff HTTP/1.1\r\n\r\n"),
            HeadError::Malformed("not UTF-8")
        );
    }
}
