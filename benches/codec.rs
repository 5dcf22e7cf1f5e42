//! Codec throughput: the wire carries at most 2500 frames/s (500000 baud), so
//! encode and decode must cost nothing next to it. Criterion reports frames/s.

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use jointd::protocol::*;

fn sample_frames() -> Vec<FrameBytes> {
    let mut frames = Vec::new();
    for id in 1..=16u8 {
        frames.push(Command::Control(Control::set_ref(id, 11520, 13106)).encode());
        frames.push(Command::Config(Config::read(id, InfoBlock::Info02)).encode());
        let info = Info02 {
            d_cur: 120,
            q_cur: -340,
            speed: 6553,
            angle: 5824,
        };
        frames.push(Reply::new(id, ReplyBody::Info02(info)).encode());
    }
    frames.push(
        Command::BroadcastPos(BroadcastPos {
            group: Group::Low,
            pos_ref: [11520; 8],
        })
        .encode(),
    );
    frames
}

fn bench_encode(c: &mut Criterion) {
    let mut g = c.benchmark_group("encode");
    g.throughput(Throughput::Elements(1));
    let cmd = Command::BroadcastPos(BroadcastPos {
        group: Group::High,
        pos_ref: [-11520; 8],
    });
    g.bench_function("broadcast_pos", |b| {
        b.iter(|| black_box(black_box(&cmd).encode()))
    });
    let ctl = Command::Control(Control::set_ref(5, -1295, 13106));
    g.bench_function("control", |b| {
        b.iter(|| black_box(black_box(&ctl).encode()))
    });
    g.finish();
}

fn bench_decode(c: &mut Criterion) {
    let frames = sample_frames();
    let mut g = c.benchmark_group("decode");
    g.throughput(Throughput::Elements(frames.len() as u64));
    g.bench_function("frame_and_message", |b| {
        b.iter(|| {
            for f in &frames {
                let frame = Frame::decode(black_box(f)).ok();
                black_box(frame.map(|f| Message::from_frame(&f)));
            }
        })
    });
    let stream: Vec<u8> = frames.iter().flatten().copied().collect();
    g.bench_function("stream", |b| {
        b.iter(|| {
            let mut d = StreamDecoder::new();
            d.push(black_box(&stream));
            let mut n = 0;
            while d.next_frame().is_some() {
                n += 1;
            }
            black_box(n)
        })
    });
    g.finish();
}

criterion_group!(benches, bench_encode, bench_decode);
criterion_main!(benches);
