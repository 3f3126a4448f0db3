//! Capture → on the wire: the pose's RTPS DATA submessage as a packet
//! socket on loopback sees it leave, timestamped by the kernel
//! (`SIOCGSTAMPNS`, the system clock, as the pose's header stamp is).
//! The pose is told from odom and tf by its serialized length (a fixed
//! layout given the frame's name) and its stamp read from its header.

use nix::libc;
use socket2::{Domain, Protocol, Socket, Type};
use std::collections::HashMap;
use std::mem::MaybeUninit;
use std::os::fd::AsRawFd;
use std::time::{Duration, Instant};

pub struct Sniffer {
    sock: Socket,
    /// The pose's CDR length after the 4-byte encapsulation header.
    pose_len: usize,
    frame_id: Vec<u8>,
}

const ETH_P_ALL: u16 = 0x0003;
const SIOCGSTAMPNS: libc::c_ulong = 0x8907;
const RTPS_DATA: u8 = 0x15;

impl Sniffer {
    pub fn open(frame_id: &str) -> std::io::Result<Sniffer> {
        let sock = Socket::new(
            Domain::from(libc::AF_PACKET),
            Type::RAW,
            Some(Protocol::from(i32::from(ETH_P_ALL.to_be()))),
        )?;
        sock.set_read_timeout(Some(Duration::from_millis(100)))?;
        // header: stamp (8), frame_id (4 + len + NUL), aligned to 8 for
        // the pose's 7 doubles and the covariance's 36.
        let head = 8 + 4 + frame_id.len() + 1;
        Ok(Sniffer {
            sock,
            pose_len: head.div_ceil(8) * 8 + 8 * (7 + 36),
            frame_id: frame_id.as_bytes().to_vec(),
        })
    }

    /// Capture → on the wire (µs) of every pose seen within `secs`: the
    /// first sighting of each stamp (lo shows a packet going out and
    /// coming in; the going out is first).
    pub fn collect(self, secs: Duration) -> Vec<f64> {
        let mut seen: HashMap<(i32, u32), f64> = HashMap::new();
        let mut buf = vec![MaybeUninit::<u8>::uninit(); 65536];
        let end = Instant::now() + secs;
        while Instant::now() < end {
            let Ok(n) = self.sock.recv(&mut buf) else {
                continue;
            };
            // SAFETY: recv initialised the first n bytes.
            let pkt: &[u8] = unsafe { std::slice::from_raw_parts(buf.as_ptr().cast(), n) };
            let Some(at) = self.stamp_now() else { continue };
            for stamp in self.poses(pkt) {
                let lat = (at - (f64::from(stamp.0) + f64::from(stamp.1) * 1e-9)) * 1e6;
                seen.entry(stamp).or_insert(lat);
            }
        }
        seen.into_values().collect()
    }

    /// The kernel's timestamp of the last packet read (unix seconds).
    fn stamp_now(&self) -> Option<f64> {
        let mut ts = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: SIOCGSTAMPNS writes one timespec.
        let r = unsafe { libc::ioctl(self.sock.as_raw_fd(), SIOCGSTAMPNS, &mut ts) };
        (r == 0).then_some(ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9)
    }

    /// The stamps of the poses in one loopback frame (Ethernet, IPv4,
    /// UDP, RTPS).
    fn poses(&self, pkt: &[u8]) -> Vec<(i32, u32)> {
        let mut out = Vec::new();
        let Some(ip) = pkt.get(14..) else { return out };
        if ip.len() < 20 || ip[0] >> 4 != 4 || ip[9] != 17 {
            return out;
        }
        let Some(rtps) = ip.get(usize::from(ip[0] & 0x0f) * 4 + 8..) else {
            return out;
        };
        if rtps.len() < 20 || &rtps[..4] != b"RTPS" {
            return out;
        }
        self.submessages(rtps, &mut out);
        out
    }

    fn submessages(&self, rtps: &[u8], out: &mut Vec<(i32, u32)>) -> Option<()> {
        let mut i = 20;
        while i + 4 <= rtps.len() {
            let (id, flags) = (rtps[i], rtps[i + 1]);
            let le = flags & 1 == 1;
            let len = usize::from(u16_at(&rtps[i + 2..], le)?);
            let body_end = if len == 0 { rtps.len() } else { i + 4 + len };
            let Some(body) = rtps.get(i + 4..body_end) else {
                break;
            };
            if id == RTPS_DATA && flags & 0x04 != 0 {
                if let Some(s) = self.pose_in(body, flags & 0x02 != 0, le) {
                    out.push(s);
                }
            }
            i = body_end;
        }
        Some(())
    }

    /// A DATA submessage's payload, if it is a pose: its stamp.
    fn pose_in(&self, body: &[u8], inline_qos: bool, le: bool) -> Option<(i32, u32)> {
        let mut at = 4 + usize::from(u16_at(body.get(2..4)?, le)?);
        if inline_qos {
            // A parameter list up to PID_SENTINEL (1).
            loop {
                let pid = u16_at(body.get(at..)?, le)?;
                let plen = usize::from(u16_at(body.get(at + 2..)?, le)?);
                at += 4 + plen;
                if pid == 1 {
                    break;
                }
            }
        }
        let payload = body.get(at..)?;
        // Encapsulation: CDR little endian (0x0001), then the padding
        // count in the options' last two bits.
        if payload.get(..2)? != [0, 1] {
            return None;
        }
        let cdr_len = payload.len().checked_sub(4 + usize::from(payload[3] & 3))?;
        let cdr = &payload[4..];
        if cdr_len != self.pose_len {
            return None;
        }
        let name_len = u32::from_le_bytes(cdr.get(8..12)?.try_into().ok()?) as usize;
        if name_len != self.frame_id.len() + 1
            || cdr.get(12..12 + self.frame_id.len())? != self.frame_id
        {
            return None;
        }
        let sec = i32::from_le_bytes(cdr.get(..4)?.try_into().ok()?);
        let nsec = u32::from_le_bytes(cdr.get(4..8)?.try_into().ok()?);
        Some((sec, nsec))
    }
}

fn u16_at(b: &[u8], le: bool) -> Option<u16> {
    let two = [*b.first()?, *b.get(1)?];
    Some(if le {
        u16::from_le_bytes(two)
    } else {
        u16::from_be_bytes(two)
    })
}
