//! Any bytes as what the autopilot's link delivers, on serial (a stream,
//! fed in pieces of any size) or UDP (datagrams): the scanner never panics,
//! counts no more garbage than it was given, and every frame it finds is
//! either refused with its reason or a reading within range. Every frame
//! also goes through a signing check (as with `[mavlink.signing]`): any
//! bytes are refused or taken, never a panic, and an unsigned frame is
//! taken only when unsigned frames are allowed (seeds/…/signed-attitude.bin
//! is signed with the key, so the fuzzer starts from the signed path).
#![no_main]
use libfuzzer_sys::fuzz_target;
use lightpose_vehicle::mav::inbound::{interpret, Input, InputConfig};
use lightpose_vehicle::mav::scan::{Framing, Scanned, Scanner};
use lightpose_vehicle::mav::signing::{Rejected, Signer, SigningConfig, SigningKey};
use lightpose_core::Angle;
use lightpose_vehicle::{NedVec, Site};

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    let framing = if mode & 1 == 0 {
        Framing::Stream
    } else {
        Framing::Datagram
    };
    // The piece size: one byte at a time up to whole bursts.
    let piece = 1 + (mode as usize >> 1) * 3;
    let cfg = InputConfig::default();
    let site = Site {
        axis_heading: Angle::from_deg(30.0),
        beacon_depth_m: 3.0,
        beacon_ned: NedVec::default(),
    };
    let mut s = Scanner::new(framing);
    let mut signer = Signer::new(SigningConfig {
        key: SigningKey::from_passphrase("fuzz"),
        link_id: 0,
        allow_unsigned: mode & 2 != 0,
    });
    for chunk in rest.chunks(piece) {
        s.push(chunk);
        while let Some(found) = s.next_frame() {
            let Scanned::Frame(f) = found else { continue };
            assert!(f.payload.len() <= 255);
            assert!(f.bytes.len() >= f.payload.len());
            let signed = f.bytes[0] == 0xFD && f.bytes[2] & 1 != 0;
            match signer.check(f.bytes) {
                // Unsigned is taken only when allowed (a signed seed carries
                // the key's signature; random ones are refused).
                Ok(()) => assert!(signed || mode & 2 != 0),
                Err(Rejected::Unsigned) => assert!(!signed && mode & 2 == 0),
                Err(_) => assert!(signed),
            }
            match interpret(&f, &cfg, &site) {
                Ok(Input::Attitude(r, w)) => {
                    assert!(r.pitch.deg().abs() <= 90.1, "{r:?}");
                    assert!(r.yaw.deg().is_finite(), "{r:?}");
                    assert!(w.is_none_or(|w| w.pitch.is_finite() && w.yaw.is_finite()), "{w:?}");
                }
                Ok(Input::Depth(d)) => assert!(d.z.is_finite(), "{d:?}"),
                Ok(Input::Temperature(c)) => assert!((-5.0..=50.0).contains(&c)),
                Ok(_) => {}
                Err(r) => assert_eq!(r.msg_id, f.msg_id),
            }
        }
        if framing == Framing::Datagram {
            s.end_of_datagram();
        }
    }
    assert!(s.garbage_bytes() <= rest.len() as u64);
});
