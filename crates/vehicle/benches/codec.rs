//! What the vehicle link costs: the frame thread's attach and offer, the
//! encoding of each outgoing message (pose → NED → covariance → MAVLink 2
//! frame), and the reading of incoming ones (framing, CRC, decode, checks),
//! which bounds the flood a link can take.

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use lightpose_core::{Angle, AttitudeReading, Frame, Pose, PoseEstimate, Status, StdDev, NDET};
use lightpose_vehicle::mav::inbound::{interpret, InputConfig};
use lightpose_vehicle::mav::outbound::{
    vision_position, vision_speed, Encoder, Outgoing, OutputConfig,
};
use lightpose_vehicle::mav::scan::{Framing, Scanned, Scanner};
use lightpose_vehicle::{Hub, MaxAge, Site};
use mavlink::dialects::ardupilotmega::{MavMessage, ATTITUDE_DATA};
use std::time::{Duration, Instant};

fn outgoing() -> Outgoing {
    Outgoing {
        seq: 1,
        t: 123.456,
        pose: Pose::new(5.0, 1.0, 0.5, Angle::from_deg(10.0), Angle::from_deg(-20.0)),
        surge: Some(0.4),
        std: [
            Some(0.2),
            Some(0.05),
            Some(0.03),
            Some(1.0),
            Some(2.0),
            Some(0.05),
        ],
        roll_std: None,
        epoch: 0,
    }
}

fn bench(c: &mut Criterion) {
    let site = Site::new(Angle::from_deg(30.0), 3.0);
    let cfg = OutputConfig::default();
    let mut enc = Encoder::new(1, 197);
    let o = outgoing();
    c.bench_function(
        "encode VISION_POSITION_ESTIMATE (NED, covariance, frame)",
        |b| {
            b.iter(|| {
                let v = vision_position(black_box(&o), &site, &cfg).unwrap();
                black_box(enc.encode(&v.message().unwrap()).len())
            })
        },
    );
    c.bench_function("encode VISION_SPEED_ESTIMATE", |b| {
        b.iter(|| {
            let v = vision_speed(black_box(&o), &site, &cfg).unwrap();
            black_box(enc.encode(&v.message().unwrap()).len())
        })
    });

    // 100 ATTITUDE datagrams: framing, CRC, decode, range checks.
    let frames: Vec<Vec<u8>> = (0..100)
        .map(|k| {
            let m = MavMessage::ATTITUDE(ATTITUDE_DATA {
                pitch: 0.001 * k as f32,
                yaw: 0.5,
                ..Default::default()
            });
            Encoder::new(1, 1).encode(&m).to_vec()
        })
        .collect();
    let input = InputConfig::default();
    let mut sc = Scanner::new(Framing::Datagram);
    let mut g = c.benchmark_group("read");
    g.throughput(Throughput::Elements(frames.len() as u64));
    g.bench_function("ATTITUDE datagrams", |b| {
        b.iter(|| {
            let mut n = 0;
            for f in &frames {
                sc.push(f);
                while let Some(Scanned::Frame(fr)) = sc.next_frame() {
                    n += interpret(&fr, &input, &site).is_ok() as u32;
                }
                sc.end_of_datagram();
            }
            black_box(n)
        })
    });
    // Issue 44's flood: one datagram of 0xFD bytes, as large as UDP
    // carries. Its first candidate ends it (it was a parse per byte).
    let flood = vec![0xFDu8; 65_507];
    g.throughput(Throughput::Bytes(flood.len() as u64));
    g.bench_function("0xFD flood datagram (65 507 bytes)", |b| {
        b.iter(|| {
            sc.push(black_box(&flood));
            let mut n = 0u32;
            while sc.next_frame().is_some() {
                n += 1;
            }
            sc.end_of_datagram();
            black_box(n)
        })
    });
    g.finish();

    let hub = Hub::new();
    hub.readings.store_attitude(
        Instant::now(),
        &AttitudeReading::new(Angle::ZERO, Angle::ZERO),
    );
    let ages = MaxAge {
        attitude: Duration::from_secs(3600),
        ..MaxAge::default()
    };
    let mut est = PoseEstimate::empty(1, 1.0, Status::Ok, "bench");
    (est.x, est.y, est.z, est.pitch_deg, est.yaw_deg) =
        (Some(5.0), Some(1.0), Some(0.5), Some(1.0), Some(2.0));
    est.std = StdDev {
        x: Some(0.1),
        ..StdDev::default()
    };
    c.bench_function("frame thread: attach + offer", |b| {
        b.iter(|| {
            let mut f = Frame::new(1, 1.0, 10, [0; NDET]);
            let a = hub.readings.attach(&mut f, Instant::now(), &ages);
            black_box((a, hub.outbox.offer(&est, 0)))
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
