//! What the page may do with `[web] control = true` (issue 43, item 4):
//! stop and start the recording, reload the calibration (as SIGHUP does),
//! check an uploaded
//! configuration (`--check-config`'s parse and validation, its one-line
//! verdict), list the recording folder and download a file of it. Without
//! `control` every one of these is refused (the page is read-only).
//!
//! Nothing a client sends reaches the frame thread: a reload is a flag the
//! supervisor takes (it builds the estimator off the frame thread, as for
//! SIGHUP); an upload is parsed here, bounded ([`MAX_UPLOAD`]) and never
//! written anywhere; a download reads only a plain file directly in the
//! recording folder, named by a name without a path.

use super::http::{self, Cut, Limits, Request};
use super::WebFeed;
use crate::config::Config;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tokio::io::AsyncReadExt;
use tokio::net::TcpStream;

/// The largest configuration accepted for a check (the shipped examples
/// are under 20 kB).
pub const MAX_UPLOAD: usize = 256 << 10;

/// Whether `req` is one of the control requests (then it is answered here,
/// or refused when control is off).
pub fn is_control(req: &Request) -> bool {
    matches!(
        (req.method.as_str(), req.path.as_str()),
        ("POST", "/v1/reload")
            | ("POST", "/v1/check-config")
            | ("GET", "/v1/recordings")
            | ("POST", "/v1/recording/start")
            | ("POST", "/v1/recording/stop")
    ) || (req.method == "GET" && req.path.starts_with("/v1/recordings/"))
}

/// Answer a control request; `head_rest` is what was read past the head
/// (the start of a body).
pub async fn answer(
    stream: &mut TcpStream,
    req: &Request,
    head_rest: &[u8],
    feed: &Arc<WebFeed>,
    limits: &Limits,
) -> Result<(), Cut> {
    if !feed.control {
        let msg = format!(
            "{} {}: the page is read-only ([web] control = false)",
            req.method, req.path
        );
        return http::send_error(stream, 403, "Forbidden", &msg, limits).await;
    }
    match (req.method.as_str(), req.path.as_str()) {
        ("POST", "/v1/reload") => {
            feed.reload.notify_one();
            tracing::info!("web: calibration reload asked from the page");
            let body = br#"{"reload":"asked"}"#;
            http::send(
                stream,
                202,
                "Accepted",
                "application/json",
                body,
                true,
                limits,
            )
            .await
        }
        ("POST", "/v1/check-config") => check_config(stream, req, head_rest, limits).await,
        ("POST", "/v1/recording/start") => recording(stream, feed, false, limits).await,
        ("POST", "/v1/recording/stop") => recording(stream, feed, true, limits).await,
        ("GET", "/v1/recordings") => list(stream, feed, limits).await,
        _ => download(stream, req, feed, limits).await,
    }
}

/// `--check-config`'s validation of the uploaded text, one line: what a
/// file with these contents would be refused for (without the machine's
/// checks: the running daemon holds its own ports).
async fn check_config(
    stream: &mut TcpStream,
    req: &Request,
    head_rest: &[u8],
    limits: &Limits,
) -> Result<(), Cut> {
    let Some(len) = req.content_length else {
        return http::send_error(
            stream,
            411,
            "Length Required",
            "a configuration upload needs its Content-Length",
            limits,
        )
        .await;
    };
    if len > MAX_UPLOAD {
        let msg = format!("the configuration is {len} bytes, over the {MAX_UPLOAD} accepted");
        return http::send_error(stream, 413, "Payload Too Large", &msg, limits).await;
    }
    let mut body = head_rest.to_vec();
    body.truncate(len);
    let rest = async {
        let mut buf = vec![0u8; 16 << 10];
        while body.len() < len {
            let n = stream.read(&mut buf).await.map_err(|_| Cut::Gone)?;
            if n == 0 {
                return Err(Cut::Gone);
            }
            body.extend_from_slice(&buf[..n.min(len - body.len())]);
        }
        Ok(())
    };
    match tokio::time::timeout(limits.head_deadline, rest).await {
        Ok(Ok(())) => {}
        Ok(Err(c)) => return Err(c),
        Err(_) => return Err(Cut::NotReading),
    }
    let verdict = match std::str::from_utf8(&body) {
        Err(e) => {
            serde_json::json!({"ok": false, "error": format!("uploaded.toml: not UTF-8 text ({e})")})
        }
        Ok(text) => match Config::parse(text, "uploaded.toml", None) {
            Ok(_) => serde_json::json!({"ok": true, "verdict": "uploaded.toml: valid"}),
            Err(e) => serde_json::json!({"ok": false, "error": e.to_string()}),
        },
    };
    let body = verdict.to_string();
    http::send(
        stream,
        200,
        "OK",
        "application/json",
        body.as_bytes(),
        true,
        limits,
    )
    .await
}

/// Stop (`paused`) or start the recording: a flag the frame path and the
/// recorder thread read (the thread completes and closes the file at a
/// stop; the next frame after a start opens a new one).
async fn recording(
    stream: &mut TcpStream,
    feed: &Arc<WebFeed>,
    pause: bool,
    limits: &Limits,
) -> Result<(), Cut> {
    let Some(rec) = &feed.recorder else {
        return http::send_error(
            stream,
            404,
            "Not Found",
            "no [recording] configured",
            limits,
        )
        .await;
    };
    let was = rec.paused.swap(pause, std::sync::atomic::Ordering::Relaxed);
    if was != pause {
        tracing::info!(
            "web: recording {} from the page",
            if pause { "stopped" } else { "started" }
        );
    }
    let body =
        serde_json::json!({ "recording": if pause { "stopped" } else { "started" } }).to_string();
    http::send(
        stream,
        202,
        "Accepted",
        "application/json",
        body.as_bytes(),
        true,
        limits,
    )
    .await
}

/// The recording folder's files: name and size.
async fn list(stream: &mut TcpStream, feed: &Arc<WebFeed>, limits: &Limits) -> Result<(), Cut> {
    let Some(dir) = &feed.recordings else {
        return http::send_error(
            stream,
            404,
            "Not Found",
            "no [recording] configured",
            limits,
        )
        .await;
    };
    let mut files = Vec::new();
    if let Ok(mut rd) = tokio::fs::read_dir(dir).await {
        while let Ok(Some(e)) = rd.next_entry().await {
            let Ok(meta) = e.metadata().await else {
                continue;
            };
            if meta.is_file() {
                files.push(serde_json::json!({"name": e.file_name().to_string_lossy(), "bytes": meta.len()}));
            }
        }
    }
    files.sort_by(|a, b| a["name"].as_str().cmp(&b["name"].as_str()));
    let body = serde_json::json!({ "dir": dir.display().to_string(), "files": files }).to_string();
    http::send(
        stream,
        200,
        "OK",
        "application/json",
        body.as_bytes(),
        true,
        limits,
    )
    .await
}

/// The file `name` of `dir`, if `name` is a plain file name there: no
/// separator, no `..`, not hidden, a regular file (a link out of the
/// folder is refused by its canonical parent).
pub fn file_in(dir: &Path, name: &str) -> Option<PathBuf> {
    let plain = !name.is_empty()
        && !name.starts_with('.')
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"._-".contains(&b));
    if !plain {
        return None;
    }
    let p = dir.join(name);
    let canon = p.canonicalize().ok()?;
    let meta = std::fs::metadata(&canon).ok()?;
    (meta.is_file() && canon.parent()? == dir.canonicalize().ok()?).then_some(canon)
}

async fn download(
    stream: &mut TcpStream,
    req: &Request,
    feed: &Arc<WebFeed>,
    limits: &Limits,
) -> Result<(), Cut> {
    let name = req.path.trim_start_matches("/v1/recordings/");
    let found = feed.recordings.as_deref().and_then(|d| file_in(d, name));
    let Some(path) = found else {
        let msg = format!("{name}: no such recording");
        return http::send_error(stream, 404, "Not Found", &msg, limits).await;
    };
    let Ok(mut f) = tokio::fs::File::open(&path).await else {
        return http::send_error(stream, 404, "Not Found", "the recording went away", limits).await;
    };
    let len = f.metadata().await.map(|m| m.len()).unwrap_or(0);
    let head = format!(
        "HTTP/1.1 200 OK\r\nContent-Type: application/octet-stream\r\nContent-Length: {len}\r\nContent-Disposition: attachment; filename=\"{name}\"\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n"
    );
    http::write(stream, head.as_bytes(), limits).await?;
    // A file still being written grows: exactly the length announced.
    let mut left = len;
    let mut buf = vec![0u8; 64 << 10];
    while left > 0 {
        let want = buf.len().min(usize::try_from(left).unwrap_or(usize::MAX));
        let n = f.read(&mut buf[..want]).await.map_err(|_| Cut::Gone)?;
        if n == 0 {
            return Err(Cut::Gone);
        }
        http::write(stream, &buf[..n], limits).await?;
        left -= n as u64;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_a_plain_file_of_the_folder_is_served() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("lightpose-1.mcap"), b"x").unwrap();
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        let outside = tempfile::NamedTempFile::new().unwrap();
        std::os::unix::fs::symlink(outside.path(), dir.path().join("link.mcap")).unwrap();
        assert!(file_in(dir.path(), "lightpose-1.mcap").is_some());
        for bad in [
            "",
            "..",
            "../etc/passwd",
            "sub",
            ".hidden",
            "link.mcap",
            "a/b",
            "nope.mcap",
            "%2e%2e",
        ] {
            assert_eq!(file_in(dir.path(), bad), None, "{bad}");
        }
    }
}
