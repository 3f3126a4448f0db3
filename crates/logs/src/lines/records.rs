//! The records a message stream declares and carries (schema, channel,
//! message, metadata), parsed from a record's body in [`McapLines`]'s
//! buffer: bounds-checked by [`Fields`], as the rest of the reader.

use super::*;

impl<R: Read> McapLines<R> {
    pub(super) fn schema(&mut self, start: usize, end: usize, offset: u64) -> Result<(), LogError> {
        let mut f = Fields::new(&self.body[start..end]);
        let parsed = (|| {
            let (id, name, encoding) = (f.u16()?, f.str()?.to_string(), f.str()?.to_string());
            // The data matters to a conversion only, which carries it.
            let data = f.u32().and_then(|n| f.take(n as usize));
            Ok::<_, String>((id, name, encoding, data.map_or(Vec::new(), <[u8]>::to_vec)))
        })();
        let (id, name, encoding, data) =
            parsed.map_err(|m| self.err(offset, format!("schema: {m}")))?;
        self.schemas.retain(|s| s.0 != id);
        self.schemas.push((id, name, encoding, data));
        Ok(())
    }

    pub(super) fn channel(
        &mut self,
        start: usize,
        end: usize,
        offset: u64,
    ) -> Result<(), LogError> {
        let mut f = Fields::new(&self.body[start..end]);
        // The metadata matters to a conversion only, which carries it.
        let parsed = (|| {
            Ok::<_, String>((
                f.u16()?,
                f.u16()?,
                f.str()?,
                f.str()?,
                f.map().unwrap_or_default(),
            ))
        })();
        let (id, schema_id, topic, encoding, metadata) =
            parsed.map_err(|m| self.err(offset, format!("channel: {m}")))?;
        let kind = match topic {
            topic::FRAME => Kind::Frame,
            topic::BURST => Kind::Burst,
            topic::DEMODULATED => Kind::Demodulated,
            topic::POSE => Kind::Pose,
            topic::IMAGE | topic::VEHICLE_POSE | topic::TRUTH_POSE | topic::TF => Kind::Derived,
            _ => Kind::Other,
        };
        self.decls.retain(|d| d.0 != id);
        if kind == Kind::Other {
            let schema = self
                .schemas
                .iter()
                .find(|s| s.0 == schema_id && schema_id != 0);
            let decl = ChannelDecl {
                topic: topic.to_string(),
                message_encoding: encoding.to_string(),
                metadata,
                schema: schema.map(|s| (s.1.clone(), s.2.clone(), s.3.clone())),
            };
            self.decls.push((id, decl));
        }
        if matches!(
            kind,
            Kind::Frame | Kind::Pose | Kind::Burst | Kind::Demodulated
        ) {
            let (want, want_se, want_me) = match kind {
                Kind::Frame => (
                    name::FRAME,
                    schema::SCHEMA_ENCODING,
                    schema::MESSAGE_ENCODING,
                ),
                Kind::Pose => (
                    name::POSE,
                    schema::SCHEMA_ENCODING,
                    schema::MESSAGE_ENCODING,
                ),
                Kind::Demodulated => (
                    name::DEMODULATED,
                    schema::SCHEMA_ENCODING,
                    schema::MESSAGE_ENCODING,
                ),
                _ => (
                    name::BURST,
                    schema::BURST_SCHEMA_ENCODING,
                    schema::BURST_MESSAGE_ENCODING,
                ),
            };
            let found = self.schemas.iter().find(|s| s.0 == schema_id);
            let ok = encoding == want_me && found.is_some_and(|s| s.1 == want && s.2 == want_se);
            if !ok {
                let (sn, se) = found.map_or(("none", ""), |s| (s.1.as_str(), s.2.as_str()));
                let msg = format!(
                    "channel {topic} has schema {sn} ({se}) and {encoding} messages; lightpose reads schema {want} ({want_se}) with {want_me} messages"
                );
                return Err(self.err(offset, msg));
            }
        }
        self.channels.retain(|c| c.0 != id);
        self.channels.push((id, kind));
        Ok(())
    }

    pub(super) fn message(
        &mut self,
        start: usize,
        end: usize,
        offset: u64,
    ) -> Result<Msg, LogError> {
        let mut f = Fields::new(&self.body[start..end]);
        let parsed = (|| {
            Ok::<_, String>(mcap::records::MessageHeader {
                channel_id: f.u16()?,
                sequence: f.u32()?,
                log_time: f.u64()?,
                publish_time: f.u64()?,
            })
        })();
        let header = parsed.map_err(|m| self.err(offset, format!("message: {m}")))?;
        let id = header.channel_id;
        let data_start = start + f.pos;
        let kind = match self.channels.iter().find(|c| c.0 == id) {
            Some(c) => c.1,
            None => {
                return Err(self.err(
                    offset,
                    format!(
                        "a message on channel {id}, which no Channel record declared before it"
                    ),
                ))
            }
        };
        Ok(Msg {
            kind,
            start: data_start,
            end,
            offset,
            header,
        })
    }

    /// Take the header from a metadata record; true when this was it.
    pub(super) fn metadata(&mut self, offset: u64) -> Result<bool, LogError> {
        let mut f = Fields::new(&self.body);
        let parsed = (|| {
            let name = f.str()?;
            if name != schema::HEADER_METADATA {
                if self.keep_carried {
                    // One that does not parse is passed over, counted.
                    if let Ok(pairs) = f.map() {
                        let name = name.to_string();
                        self.carried.push(Carried::Metadata { name, pairs });
                    }
                }
                return Ok(None);
            }
            let len = f.u32()? as usize;
            let mut m = Fields::new(f.take(len)?);
            while m.pos < m.b.len() {
                let (k, v) = (m.str()?, m.str()?);
                if k == schema::HEADER_KEY {
                    return Ok(Some(v.to_string()));
                }
            }
            Err(format!("has no key {}", schema::HEADER_KEY))
        })();
        match parsed {
            Ok(Some(text)) if self.header.is_none() => {
                self.header = Some((offset, text));
                Ok(true)
            }
            Ok(_) => {
                self.other += 1;
                Ok(false)
            }
            Err(m) => Err(self.err(offset, format!("metadata {}: {m}", schema::HEADER_METADATA))),
        }
    }
}
