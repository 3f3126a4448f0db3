//! A FRAME line as serde_json reads it, without the heap: replay makes a
//! log the daemon's frame source, and the hot path does not allocate per
//! frame. The line is deserialized from the reader's own buffer into fixed
//! fields (the class borrowed from the line, the counts in an array, each
//! reading's numbers by name), where a `serde_json::Value` per reading (a
//! map, its keys and its `std` map) and a `Vec` of counts took 26
//! allocations a frame.
//!
//! Everything is read as `Value` read it, so that a line means what it
//! meant: the same grammar (`deserialize_any`, so a number out of range in
//! a field nobody reads still refuses the line), the last of a repeated key
//! wins, a number is any JSON number (`as_f64`), and what a reader refuses
//! is told apart as before (absent, null, a number, anything else). Only a
//! line that is refused (a bad count is quoted as its `Value`) or a string
//! with escapes allocates.

use crate::NDET;
use serde::de::{self, Deserialize, Deserializer, MapAccess, SeqAccess, Visitor};
use std::borrow::Cow;
use std::fmt;

/// A line's fields, borrowed from it where they are text.
#[derive(serde::Deserialize)]
pub(super) struct RawLine<'a> {
    #[serde(borrow)]
    pub class: Option<Text<'a>>,
    pub seq: Option<serde_json::Value>,
    pub t: Option<f64>,
    pub counts: Option<Counts>,
    /// A BURST's `[25 arrays of N integers]` (spec v3).
    pub samples: Option<SampleArrays>,
    /// A demodulated FRAME's beacons, ambient and clipped (spec v3).
    #[serde(borrow)]
    pub beacons: Option<DemodBeacons<'a>>,
    pub ambient: Option<Nums>,
    pub clipped: Option<Counts>,
    pub temp_c: Option<f64>,
    pub truth: Option<super::RawTruth>,
    // The vehicle's own readings are taken apart by hand: a reading that is
    // malformed costs that reading (counted), never the frame's light.
    pub attitude: Option<Reading>,
    pub depth: Option<Reading>,
    pub velocity: Option<Reading>,
    /// A frame-level `std` object (`{"z":..,"fwd":..,..}`) for readings that
    /// carry none of their own: FORMATS.md allows either place.
    pub std: Option<Std>,
}

/// A string, borrowed from the line unless it had escapes.
pub(super) struct Text<'a>(pub Cow<'a, str>);

impl<'de: 'a, 'a> Deserialize<'de> for Text<'a> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Cow<'de, str>;
            // As `String` says it.
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a string")
            }
            fn visit_borrowed_str<E: de::Error>(self, v: &'de str) -> Result<Self::Value, E> {
                Ok(Cow::Borrowed(v))
            }
            fn visit_str<E: de::Error>(self, v: &str) -> Result<Self::Value, E> {
                Ok(Cow::Owned(v.to_owned()))
            }
            fn visit_string<E: de::Error>(self, v: String) -> Result<Self::Value, E> {
                Ok(Cow::Owned(v))
            }
        }
        d.deserialize_string(V).map(Text)
    }
}

/// The `counts` array: how many values it held, the first [`NDET`] as
/// non-negative integers where they are (whole floats too), and the first of those that is
/// not one (for the refusal to quote).
pub(super) struct Counts {
    pub len: usize,
    pub values: [Option<u64>; NDET],
    pub first_other: Option<serde_json::Value>,
}

impl<'de> Deserialize<'de> for Counts {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Counts;
            // As `Vec` says it.
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a sequence")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Counts, A::Error> {
                let mut c = Counts {
                    len: 0,
                    values: [None; NDET],
                    first_other: None,
                };
                // A number is a `Value` without the heap.
                while let Some(v) = seq.next_element::<serde_json::Value>()? {
                    if let Some(slot) = c.values.get_mut(c.len) {
                        // A whole number written as a float (46.0, as a
                        // writer that keeps counts in floats writes them)
                        // is that integer; 46.5 is not.
                        *slot = v.as_u64().or_else(|| {
                            v.as_f64()
                                .filter(|f| *f >= 0.0 && f.fract() == 0.0 && *f <= 65535.0)
                                .map(|f| f as u64)
                        });
                        if slot.is_none() && c.first_other.is_none() {
                            c.first_other = Some(v);
                        }
                    }
                    c.len += 1;
                }
                Ok(c)
            }
        }
        d.deserialize_seq(V)
    }
}

/// 25 numbers (a demodulated frame's `amplitude`, `std`, `ambient`): how
/// many there were, the first [`NDET`], and the index of the first that is
/// no finite number.
pub(super) struct Nums {
    pub len: usize,
    pub values: [f64; NDET],
    pub first_bad: Option<usize>,
}

impl<'de> Deserialize<'de> for Nums {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Nums;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a sequence")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Nums, A::Error> {
                let mut n = Nums {
                    len: 0,
                    values: [0.0; NDET],
                    first_bad: None,
                };
                while let Some(v) = seq.next_element::<Num>()? {
                    match (n.values.get_mut(n.len), v) {
                        (Some(slot), Num::Number(x)) => *slot = x,
                        (Some(_), _) if n.first_bad.is_none() => n.first_bad = Some(n.len),
                        _ => {}
                    }
                    n.len += 1;
                }
                Ok(n)
            }
        }
        d.deserialize_seq(V)
    }
}

std::thread_local! {
    /// The buffer the next BURST line's samples are read into: handed to
    /// the reader's burst, whose old buffer comes back here, so that a log
    /// of bursts is read without an allocation per line.
    static SPARE: std::cell::Cell<Vec<u16>> = const { std::cell::Cell::new(Vec::new()) };
}

/// Give a samples buffer back for the next line.
pub(super) fn give_back(v: Vec<u16>) {
    SPARE.with(|s| s.set(v));
}

/// Most values a BURST's samples may hold before the line is refused
/// unread further (25 channels of the most samples a frame may have).
const MAX_SAMPLE_VALUES: usize = NDET * crate::samples::MAX_SAMPLES_PER_FRAME;

/// A BURST's `samples`: every value in one channel-major buffer, how many
/// arrays there were and the length of the first [`NDET`], and the first
/// value that is no count (channel, index, the value).
pub(super) struct SampleArrays {
    pub flat: Vec<u16>,
    pub channels: usize,
    pub lens: [usize; NDET],
    pub first_bad: Option<(usize, usize, serde_json::Value)>,
    /// More values than [`MAX_SAMPLE_VALUES`].
    pub too_many: bool,
}

/// One channel's array, appended to the flat buffer.
struct Channel<'s>(&'s mut SampleArrays);

impl<'de> de::DeserializeSeed<'de> for Channel<'_> {
    type Value = ();
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_seq(self)
    }
}

impl<'de> Visitor<'de> for Channel<'_> {
    type Value = ();
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("an array of samples")
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let s = self.0;
        let k = s.channels;
        let mut len = 0;
        while let Some(v) = seq.next_element::<serde_json::Value>()? {
            let c = v.as_u64().or_else(|| {
                v.as_f64()
                    .filter(|f| *f >= 0.0 && f.fract() == 0.0 && *f <= 65535.0)
                    .map(|f| f as u64)
            });
            match c {
                Some(c) if c <= u16::MAX as u64 => {
                    if s.flat.len() < MAX_SAMPLE_VALUES {
                        s.flat.push(c as u16);
                    } else {
                        s.too_many = true;
                    }
                }
                _ => {
                    if s.first_bad.is_none() {
                        s.first_bad = Some((k, len, v));
                    }
                    // Keep the layout: the line is refused anyway.
                    if s.flat.len() < MAX_SAMPLE_VALUES {
                        s.flat.push(0);
                    }
                }
            }
            len += 1;
        }
        if let Some(l) = s.lens.get_mut(k) {
            *l = len;
        }
        s.channels += 1;
        Ok(())
    }
}

impl<'de> Deserialize<'de> for SampleArrays {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = SampleArrays;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a sequence of arrays")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<SampleArrays, A::Error> {
                let mut flat = SPARE.with(|s| s.take());
                flat.clear();
                let mut s = SampleArrays {
                    flat,
                    channels: 0,
                    lens: [0; NDET],
                    first_bad: None,
                    too_many: false,
                };
                while seq.next_element_seed(Channel(&mut s))?.is_some() {}
                Ok(s)
            }
        }
        d.deserialize_seq(V)
    }
}

/// One beacon of a demodulated frame as its line gives it.
#[derive(serde::Deserialize, Default)]
pub(super) struct DemodBeacon<'a> {
    #[serde(borrow)]
    pub id: Option<Text<'a>>,
    pub amplitude: Option<Nums>,
    pub std: Option<Nums>,
}

/// A demodulated frame's `beacons`: how many, the first
/// [`MAX_BEACONS`](crate::samples::MAX_BEACONS).
pub(super) struct DemodBeacons<'a> {
    pub len: usize,
    pub items: [DemodBeacon<'a>; crate::samples::MAX_BEACONS],
}

impl<'de: 'a, 'a> Deserialize<'de> for DemodBeacons<'a> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V<'a>(std::marker::PhantomData<&'a ()>);
        impl<'de: 'a, 'a> Visitor<'de> for V<'a> {
            type Value = DemodBeacons<'a>;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a sequence of beacon objects")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
                let mut out = DemodBeacons {
                    len: 0,
                    items: Default::default(),
                };
                loop {
                    if let Some(slot) = out.items.get_mut(out.len) {
                        match seq.next_element::<DemodBeacon<'a>>()? {
                            Some(b) => *slot = b,
                            None => break,
                        }
                    } else if seq.next_element::<Skip>()?.is_none() {
                        break;
                    }
                    out.len += 1;
                }
                Ok(out)
            }
        }
        d.deserialize_seq(V(std::marker::PhantomData))
    }
}

/// A number field of a reading or of a `std` object, as its `Value` was
/// told apart.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) enum Num {
    #[default]
    Absent,
    Null,
    Number(f64),
    /// A string, a boolean, an array or an object.
    Other,
}

/// The keys a reading or a `std` object may name: attitude's (with spec
/// v3's roll), depth's and velocity's.
pub(super) const KEYS: [&str; 7] = ["pitch", "yaw", "z", "fwd", "right", "down", "roll"];

/// The named numbers of a reading or of a `std` object ([`KEYS`]).
#[derive(Debug, Default, Clone, Copy)]
pub(super) struct Fields([Num; KEYS.len()]);

impl Fields {
    /// The field `key` (one of [`KEYS`]; any other is absent).
    pub fn get(&self, key: &str) -> Num {
        KEYS.iter()
            .position(|&k| k == key)
            .map_or(Num::Absent, |i| self.0[i])
    }
}

/// A reading (`attitude`, `depth`, `velocity`): an object with its numbers
/// and its own `std`, or something else.
// A value on the stack, parsed and used per line: boxing it would
// allocate per frame.
#[allow(clippy::large_enum_variant)]
#[derive(Debug)]
pub(super) enum Reading {
    NotObject,
    Object { fields: Fields, std: Std },
}

/// A `std` object (a reading's, or the frame's), or what stands there.
#[derive(Debug)]
pub(super) enum Std {
    Absent,
    Null,
    NotObject,
    Object(Fields),
}

/// A key of a reading's object: one of [`KEYS`], `std` (read only where
/// `std_too`), or another (passed over).
enum Key {
    Field(usize),
    Std,
    Other,
}

struct KeySeed {
    std_too: bool,
}

impl<'de> de::DeserializeSeed<'de> for KeySeed {
    type Value = Key;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Key, D::Error> {
        // As `Value` reads a key.
        d.deserialize_str(self)
    }
}

impl<'de> Visitor<'de> for KeySeed {
    type Value = Key;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a string key")
    }
    fn visit_str<E: de::Error>(self, v: &str) -> Result<Key, E> {
        Ok(match KEYS.iter().position(|&k| k == v) {
            Some(i) => Key::Field(i),
            None if self.std_too && v == "std" => Key::Std,
            None => Key::Other,
        })
    }
}

/// The entries of an object: its [`KEYS`] into `fields` and, where
/// `std` is given, its `std` there; the last of a repeated key wins, as in
/// a `Value`'s map.
fn read_object<'de, A: MapAccess<'de>>(
    mut map: A,
    fields: &mut Fields,
    mut std: Option<&mut Std>,
) -> Result<(), A::Error> {
    let std_too = std.is_some();
    while let Some(key) = map.next_key_seed(KeySeed { std_too })? {
        match key {
            Key::Field(i) => fields.0[i] = map.next_value()?,
            Key::Std => match std.as_deref_mut() {
                Some(s) => *s = map.next_value()?,
                None => map.next_value::<Skip>().map(drop)?,
            },
            Key::Other => map.next_value::<Skip>().map(drop)?,
        }
    }
    Ok(())
}

/// Any JSON value, parsed as a `Value` would be and dropped as it goes.
struct Skip;

impl<'de> Deserialize<'de> for Skip {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(Kind).map(|_| Skip)
    }
}

/// What a value is, as far as a reading cares: a number (with its value,
/// `as_f64`), null, an object (its entries are read by the caller) or
/// something else. Arrays and objects met here are walked element by
/// element without being kept.
#[derive(Clone, Copy)]
struct Kind;

impl<'de> Visitor<'de> for Kind {
    type Value = Num;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("any valid JSON value")
    }
    fn visit_bool<E: de::Error>(self, _: bool) -> Result<Num, E> {
        Ok(Num::Other)
    }
    fn visit_i64<E: de::Error>(self, v: i64) -> Result<Num, E> {
        Ok(Num::Number(v as f64))
    }
    fn visit_u64<E: de::Error>(self, v: u64) -> Result<Num, E> {
        Ok(Num::Number(v as f64))
    }
    fn visit_f64<E: de::Error>(self, v: f64) -> Result<Num, E> {
        // `Value` makes a non-finite number null (serde_json never gives one).
        Ok(if v.is_finite() {
            Num::Number(v)
        } else {
            Num::Null
        })
    }
    fn visit_str<E: de::Error>(self, _: &str) -> Result<Num, E> {
        Ok(Num::Other)
    }
    fn visit_unit<E: de::Error>(self) -> Result<Num, E> {
        Ok(Num::Null)
    }
    fn visit_none<E: de::Error>(self) -> Result<Num, E> {
        Ok(Num::Null)
    }
    fn visit_some<D: Deserializer<'de>>(self, d: D) -> Result<Num, D::Error> {
        d.deserialize_any(self)
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Num, A::Error> {
        while seq.next_element::<Skip>()?.is_some() {}
        Ok(Num::Other)
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Num, A::Error> {
        while map.next_key_seed(KeySeed { std_too: false })?.is_some() {
            map.next_value::<Skip>()?;
        }
        Ok(Num::Other)
    }
}

impl<'de> Deserialize<'de> for Num {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(Kind)
    }
}

/// A visitor of a reading or `std` object: the object's entries are read
/// into fields; any other value is walked as [`Kind`] walks it.
struct ObjectOr<T> {
    object: fn(Fields, Std) -> T,
    other: fn(Num) -> T,
    std_too: bool,
}

impl<'de, T> Visitor<'de> for ObjectOr<T> {
    type Value = T;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("any valid JSON value")
    }
    fn visit_bool<E: de::Error>(self, v: bool) -> Result<T, E> {
        Kind.visit_bool(v).map(self.other)
    }
    fn visit_i64<E: de::Error>(self, v: i64) -> Result<T, E> {
        Kind.visit_i64(v).map(self.other)
    }
    fn visit_u64<E: de::Error>(self, v: u64) -> Result<T, E> {
        Kind.visit_u64(v).map(self.other)
    }
    fn visit_f64<E: de::Error>(self, v: f64) -> Result<T, E> {
        Kind.visit_f64(v).map(self.other)
    }
    fn visit_str<E: de::Error>(self, v: &str) -> Result<T, E> {
        Kind.visit_str(v).map(self.other)
    }
    fn visit_unit<E: de::Error>(self) -> Result<T, E> {
        Kind.visit_unit().map(self.other)
    }
    fn visit_none<E: de::Error>(self) -> Result<T, E> {
        Kind.visit_none().map(self.other)
    }
    fn visit_some<D: Deserializer<'de>>(self, d: D) -> Result<T, D::Error> {
        d.deserialize_any(self)
    }
    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<T, A::Error> {
        Kind.visit_seq(seq).map(self.other)
    }
    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<T, A::Error> {
        let (mut fields, mut std) = (Fields::default(), Std::Absent);
        let std_slot = self.std_too.then_some(&mut std);
        read_object(map, &mut fields, std_slot)?;
        Ok((self.object)(fields, std))
    }
}

impl<'de> Deserialize<'de> for Reading {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(ObjectOr {
            object: |fields, std| Reading::Object { fields, std },
            other: |_| Reading::NotObject,
            std_too: true,
        })
    }
}

impl<'de> Deserialize<'de> for Std {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(ObjectOr {
            object: |fields, _| Std::Object(fields),
            other: |n| match n {
                Num::Null => Std::Null,
                _ => Std::NotObject,
            },
            std_too: false,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reading(json: &str) -> Reading {
        serde_json::from_str(json).unwrap()
    }

    #[test]
    fn a_reading_is_told_apart_as_its_value_was() {
        let Reading::Object { fields, std } =
            reading(r#"{"z":1,"z":2.5,"fwd":"x","right":null,"down":[1,{"a":2}],"q":{}}"#)
        else {
            panic!("an object");
        };
        assert_eq!(fields.get("z"), Num::Number(2.5), "the last of a key wins");
        assert_eq!(fields.get("fwd"), Num::Other);
        assert_eq!(fields.get("right"), Num::Null);
        assert_eq!(fields.get("down"), Num::Other);
        assert_eq!(fields.get("pitch"), Num::Absent);
        assert!(matches!(std, Std::Absent));
        assert!(matches!(reading("[1,2]"), Reading::NotObject));
        assert!(matches!(reading("\"a\""), Reading::NotObject));
        let Reading::Object { std, .. } = reading(r#"{"std":{"z":-1,"std":3}}"#) else {
            panic!("an object");
        };
        let Std::Object(s) = std else {
            panic!("a std object")
        };
        assert_eq!(s.get("z"), Num::Number(-1.0));
        let Reading::Object { std, .. } = reading(r#"{"std":null}"#) else {
            panic!("an object");
        };
        assert!(matches!(std, Std::Null));
        let Reading::Object { fields, .. } = reading(r#"{"\u007a":3}"#) else {
            panic!("an object");
        };
        assert_eq!(fields.get("z"), Num::Number(3.0), "an escaped key");
        // The grammar of a Value: a number out of range anywhere refuses.
        assert!(serde_json::from_str::<Reading>(r#"{"q":[1e400]}"#).is_err());
    }
}
