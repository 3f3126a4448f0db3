//! What a client says and what it is told: the greeting (`serverInfo`,
//! `advertise`), `subscribe` / `unsubscribe`, and the short warning
//! `status` for anything else.

use super::STATUS_TEXT;
use crate::outputs::live::hub::{Client, Hub};
use lightpose_logs::schema::{MESSAGE_ENCODING, SCHEMA_ENCODING};
use lightpose_logs::Channel;
use serde::Deserialize;
use serde_json::json;
use std::borrow::Cow;
use tokio_tungstenite::tungstenite::Message as Ws;

/// `serverInfo` and `advertise`, the first two messages of a session.
pub fn greeting(session: &str) -> [String; 2] {
    let info = json!({
        "op": "serverInfo",
        "name": format!("lightposed {}", env!("CARGO_PKG_VERSION")),
        "capabilities": [],
        "metadata": {},
        "sessionId": session,
    });
    let channels: Vec<_> = Channel::ALL
        .iter()
        .enumerate()
        .map(|(i, c)| {
            json!({
                "id": i + 1,
                "topic": c.topic(),
                "encoding": MESSAGE_ENCODING,
                "schemaName": c.schema_name(),
                "schemaEncoding": SCHEMA_ENCODING,
                "schema": c.schema(),
            })
        })
        .collect();
    let adv = json!({"op": "advertise", "channels": channels});
    [info.to_string(), adv.to_string()]
}

/// What a client may send (the ops a live view needs).
#[derive(Deserialize)]
#[serde(tag = "op", rename_all = "camelCase")]
pub(super) enum Request_ {
    Subscribe {
        subscriptions: Vec<Subscription>,
    },
    #[serde(rename_all = "camelCase")]
    Unsubscribe {
        subscription_ids: Vec<u32>,
    },
}

#[derive(Deserialize)]
#[serde(rename_all = "camelCase")]
pub(super) struct Subscription {
    id: u32,
    channel_id: u64,
}

/// The index of channel `id` (advertised from 1): `None` for 0 and for
/// an id beyond `usize`, which must not wrap (on 32-bit ARM 2³² + 1 would
/// be channel 1).
pub(super) fn channel_index(id: u64) -> Option<usize> {
    let i = usize::try_from(id.checked_sub(1)?).ok()?;
    (i < Channel::ALL.len()).then_some(i)
}

/// A warning `status` message for the client, its text cut to
/// [`STATUS_TEXT`].
pub(super) fn warning(msg: &str) -> Ws {
    let msg = clip(msg, STATUS_TEXT);
    Ws::text(json!({"op": "status", "level": 1, "message": msg}).to_string())
}

/// `s` cut to `max` bytes (at a character), saying how much was cut.
pub(super) fn clip(s: &str, max: usize) -> Cow<'_, str> {
    if s.len() <= max {
        return Cow::Borrowed(s);
    }
    let end = (0..=max)
        .rev()
        .find(|&i| s.is_char_boundary(i))
        .unwrap_or(0);
    Cow::Owned(format!("{}… ({} bytes more)", &s[..end], s.len() - end))
}

/// The warning for a binary message: the client messages of the protocol
/// that are binary (publishing, service calls) are not served.
pub(super) fn binary_warning(len: usize) -> Ws {
    warning(&format!(
        "binary message of {len} bytes not understood (lightposed takes subscribe and unsubscribe, as text)"
    ))
}

/// Act on one text message; a reply when there is something to say.
pub(super) fn request(hub: &Hub, c: &Client, text: &str) -> Option<Ws> {
    match serde_json::from_str::<Request_>(text) {
        Ok(Request_::Subscribe { subscriptions }) => {
            let unknown: Vec<u64> = subscriptions
                .iter()
                .filter(|s| {
                    let index = channel_index(s.channel_id);
                    !index.is_some_and(|i| c.subscribe(hub, s.id, i))
                })
                .map(|s| s.channel_id)
                .collect();
            (!unknown.is_empty()).then(|| warning(&format!("no channel {unknown:?}")))
        }
        Ok(Request_::Unsubscribe { subscription_ids }) => {
            for id in subscription_ids {
                c.unsubscribe(hub, id);
            }
            None
        }
        Err(e) => Some(warning(&format!(
            "not understood (lightposed takes subscribe and unsubscribe): {e}"
        ))),
    }
}
