//! A device power cycle, an unplugged bus, and a long mixed run: the bus
//! recovers by itself and nothing ever collides.

mod support;

use std::time::{Duration, Instant};

use jointd::bus::handle::{BusEvent, DisabledReason, LinkState, ResetSignal};
use jointd::bus::{spawn_bus_on, BusConfig, BusError};
use jointd::protocol::status::fsm;
use jointd::protocol::{Command, ConfigParam, Frame, InfoBlock};
use jointd::sim::{Fault, Simulator};
use jointd::transport::Transport;
use support::bus::*;

#[tokio::test]
async fn a_power_cycled_device_goes_offline_and_comes_back_by_itself() {
    let mut sim_cfg = sim_config(&[1, 2, 3], BAUD);
    // A boot long enough for the device to miss three polls, each given up
    // on after 250 ms: the others miss three only if the simulator is held
    // back for most of a second. An offline device is asked again 20
    // timeouts later (5 s), inside the wait for it to come back if its
    // announcement meets a poll. The bus starts once the first boot is over,
    // so that one costs no polls.
    sim_cfg.boot_delay = Duration::from_secs(2);
    let rig = rig_after_boot(sim_cfg, |cfg| {
        cfg.timing.reply_margin_us = 250_000;
        cfg.ids = vec![1, 2, 3];
    });
    rig.online(3).await;
    let mut events = rig.bus.events();
    rig.sim.inject(Fault::PowerCycle { dev_id: 2 });
    event(&mut events, "device 2 offline", |e| {
        matches!(e, BusEvent::DeviceOffline { dev_id: 2, .. })
    })
    .await;
    let back = event(&mut events, "device 2 online", |e| {
        matches!(e, BusEvent::DeviceOnline { dev_id: 2, .. })
            || matches!(e, BusEvent::DeviceOffline { dev_id: 1 | 3, .. })
    })
    .await;
    assert!(
        matches!(back, BusEvent::DeviceOnline { dev_id: 2, .. }),
        "{back:?}"
    );
    let snap = rig.online(3).await;
    assert_eq!(
        snap.devices[&2].target_sent, None,
        "a rebooted device holds no target"
    );
}

#[tokio::test]
async fn an_unplugged_bus_goes_down_and_resumes_when_plugged_back() {
    let rig = rig(&[1, 2]);
    rig.online(2).await;
    let mut events = rig.bus.events();
    rig.sim.inject(Fault::Unplug);
    event(&mut events, "bus down", |e| {
        matches!(e, BusEvent::BusDown { .. })
    })
    .await;
    let snap = rig
        .until("down with every device offline", |s| {
            matches!(s.link, LinkState::Down { .. }) && s.devices.values().all(|d| !d.online)
        })
        .await;
    assert_eq!(snap.devices.len(), 2, "devices stay known while down");
    let down = rig.bus.read_info(1, InfoBlock::Info01).await;
    assert!(matches!(down, Err(BusError::Down { .. })), "{down:?}");

    rig.sim.inject(Fault::Replug);
    event(&mut events, "bus up", |e| {
        matches!(e, BusEvent::BusUp { .. })
    })
    .await;
    rig.online(2).await;
    rig.bus.read_info(1, InfoBlock::Info01).await.unwrap();
    assert!(rig.bus.snapshot().counters.reconnects >= 1);
}

#[tokio::test]
async fn one_bus_going_down_leaves_another_running() {
    let a = rig(&[1, 2]);
    let b = rig(&[1, 2]);
    a.online(2).await;
    b.online(2).await;
    a.sim.inject(Fault::Unplug);
    a.until("bus a down", |s| matches!(s.link, LinkState::Down { .. }))
        .await;
    let mark = Instant::now();
    b.until("bus b polling on", |s| {
        s.link == LinkState::Up
            && s.devices
                .values()
                .all(|d| d.online && d.info02.is_some_and(|(_, at)| at > mark))
    })
    .await;
    b.bus.read_info(2, InfoBlock::Info01).await.unwrap();
}

#[tokio::test]
async fn a_bus_on_an_in_memory_line_survives_a_hangup() {
    let (sim, host) = Simulator::spawn_memory(sim_config(&[4, 5], BAUD)).unwrap();
    let mut cfg = BusConfig::new("mem", "memory", BAUD);
    cfg.ids = vec![4, 5];
    let (bus, thread) = spawn_bus_on(cfg, Box::new(host)).unwrap();
    let rig = Rig {
        sim,
        bus,
        thread: Some(thread),
    };
    rig.online(2).await;
    rig.sim.inject(Fault::Unplug);
    rig.until("down", |s| matches!(s.link, LinkState::Down { .. }))
        .await;
    rig.sim.inject(Fault::Replug);
    rig.until("up again", |s| s.link == LinkState::Up).await;
    rig.online(2).await;
}

/// On the in-memory line: a collision count is judged there (see [`rig_in_memory`]).
#[tokio::test]
async fn a_long_mixed_run_of_setpoints_polls_and_config_never_collides() {
    let ids: Vec<u8> = (1..=16).collect();
    let rig = rig_in_memory(&ids);
    rig.online(16).await;
    rig.enable_all(16).await;
    let start = Instant::now();
    let client = TargetStream::start(rig.bus.clone(), ids.clone(), Duration::from_millis(1));
    let blocks = [
        InfoBlock::Info03,
        InfoBlock::Info04,
        InfoBlock::Info05,
        InfoBlock::Info06,
    ];
    let mut ops = 0u16;
    while start.elapsed() < Duration::from_secs(3) {
        let id = ids[usize::from(ops) % ids.len()];
        rig.bus
            .read_info(id, blocks[usize::from(ops) % blocks.len()])
            .await
            .unwrap();
        rig.bus
            .write_config(id, ConfigParam::PosLpf((ops % 4) as u8))
            .await
            .unwrap();
        ops += 1;
    }
    let writes = client.finish();
    rig.bus.disable(jointd::bus::Targets::All).await.unwrap();
    assert!(writes > 1000, "client wrote {writes}");

    let cmds: Vec<Command> = rig
        .host_frames_since(start)
        .iter()
        .filter_map(|f| Frame::decode(&f.bytes).ok())
        .filter_map(|f| Command::from_frame(&f).ok())
        .collect();
    let count = |pred: fn(&Command) -> bool| cmds.iter().filter(|c| pred(c)).count();
    let broadcasts = count(|c| matches!(c, Command::BroadcastPos(_)));
    let reads = count(|c| matches!(c, Command::Config(c) if c.param.is_read()));
    let writes = count(|c| matches!(c, Command::Config(c) if !c.param.is_read()));
    // A real mix, whatever share of the CPU a loaded machine gave the run.
    assert!(
        broadcasts > 100 && reads > 100 && writes >= usize::from(ops),
        "{broadcasts} broadcasts, {reads} reads, {writes} writes"
    );
    rig.assert_no_collisions();
}

/// A line whose driver has a bug: its `panic_at`-th write panics, once.
struct PanicsOnce {
    inner: Box<dyn Transport>,
    writes: u32,
    panic_at: u32,
}

impl Transport for PanicsOnce {
    fn write_all(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.writes += 1;
        if self.writes == self.panic_at {
            panic!("driver bug on write {}", self.writes);
        }
        self.inner.write_all(bytes)
    }
    fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> std::io::Result<usize> {
        self.inner.read_timeout(buf, timeout)
    }
    fn set_baud(&mut self, baud: u32) -> std::io::Result<()> {
        self.inner.set_baud(baud)
    }
    fn baud(&self) -> u32 {
        self.inner.baud()
    }
    fn discard_input(&mut self) -> std::io::Result<()> {
        self.inner.discard_input()
    }
}

#[tokio::test]
async fn a_panic_in_the_owner_takes_the_bus_down_and_it_comes_back() {
    let (sim, host) = Simulator::spawn_memory(sim_config(&[4, 5], BAUD)).unwrap();
    let mut cfg = BusConfig::new("mem", "memory", BAUD);
    cfg.ids = vec![4, 5];
    cfg.timing.reply_margin_us = TEST_REPLY_MARGIN_US;
    let line = PanicsOnce {
        inner: Box::new(host),
        writes: 0,
        panic_at: 50,
    };
    let (bus, thread) = spawn_bus_on(cfg, Box::new(line)).unwrap();
    let rig = Rig {
        sim,
        bus,
        thread: Some(thread),
    };
    let mut events = rig.bus.events();
    rig.until("the panic caught", |s| s.counters.owner_panics == 1)
        .await;
    rig.until("up again", |s| s.link == LinkState::Up).await;
    rig.online(2).await;
    // The owner thread lives on and still answers requests.
    assert!(!rig.thread.as_ref().unwrap().is_finished());
    rig.bus
        .read_info(4, InfoBlock::Info03)
        .await
        .expect("read after recovery");
    let mut down = Vec::new();
    while let Ok(ev) = events.try_recv() {
        if let BusEvent::BusDown { reason, .. } = ev {
            down.push(reason);
        }
    }
    assert!(
        down.iter()
            .any(|r| r.contains("internal error: driver bug")),
        "subscribers heard the bus go down and why: {down:?}"
    );
}

/// Every `DeviceReset` heard within `quiet` after the first one.
async fn resets(
    events: &mut tokio::sync::broadcast::Receiver<BusEvent>,
    quiet: Duration,
) -> Vec<BusEvent> {
    let first = event(events, "a device reset", |e| {
        matches!(e, BusEvent::DeviceReset { .. })
    })
    .await;
    let mut all = vec![first];
    let end = tokio::time::Instant::now() + quiet;
    while let Ok(Ok(ev)) = tokio::time::timeout_at(end, events.recv()).await {
        if matches!(ev, BusEvent::DeviceReset { .. }) {
            all.push(ev);
        }
    }
    all
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_power_cut_of_an_enabled_joint_is_reported_once_and_shown_disabled() {
    let rig = rig_with(sim_config(&[1, 2], BAUD), |c| c.ids = vec![1, 2]);
    rig.online(2).await;
    rig.enable_all(2).await;
    rig.bus.set_targets(&[(2, target(40.0))]);
    let mut events = rig.bus.events();
    rig.sim.inject(Fault::PowerCycle { dev_id: 2 });
    let seen = resets(&mut events, Duration::from_millis(300)).await;
    assert_eq!(seen.len(), 1, "one event per reset: {seen:?}");
    let BusEvent::DeviceReset {
        dev_id,
        state_before,
        state,
        ..
    } = &seen[0]
    else {
        unreachable!()
    };
    assert_eq!((*dev_id, *state_before, *state), (2, "run", "ready"));
    let d = rig.bus.snapshot().devices[&2].clone();
    assert_eq!(d.resets, 1);
    assert_eq!(d.disabled_reason, Some(DisabledReason::Reset));
    assert_eq!(d.target_sent, None);
    assert_eq!(
        rig.bus.shared().setpoints.get(2),
        None,
        "stored target gone"
    );
    let other = &rig.bus.snapshot().devices[&1];
    assert_eq!((other.resets, other.disabled_reason), (0, None));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_power_cut_whose_announcement_went_unheard_is_seen_in_the_state() {
    let rig = rig_with(sim_config(&[1], BAUD), |c| c.ids = vec![1]);
    rig.online(1).await;
    rig.enable_all(1).await;
    let mut events = rig.bus.events();
    // Unplugged while the device reboots: its announcement reaches nobody.
    rig.sim.inject(Fault::Unplug);
    rig.until("down", |s| matches!(s.link, LinkState::Down { .. }))
        .await;
    rig.sim.inject(Fault::PowerCycle { dev_id: 1 });
    rig.sim_until("device 1 booted", |sim| {
        sim.device(1).is_some_and(|d| !d.booting)
    });
    rig.sim.inject(Fault::Replug);
    let seen = resets(&mut events, Duration::from_millis(200)).await;
    assert_eq!(seen.len(), 1, "{seen:?}");
    assert!(
        matches!(
            seen[0],
            BusEvent::DeviceReset {
                dev_id: 1,
                seen: ResetSignal::StateDropped,
                state_before: "run",
                ..
            }
        ),
        "{seen:?}"
    );
    let snap = rig
        .until("reset shown", |s| s.devices[&1].resets == 1)
        .await;
    let d = &snap.devices[&1];
    assert_eq!(d.disabled_reason, Some(DisabledReason::Reset));
    assert!(d.info01.is_some_and(|(i, _)| i.fsm == fsm::READY));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn disabling_and_estopping_are_no_resets() {
    let rig = rig_with(sim_config(&[1, 2], BAUD), |c| c.ids = vec![1, 2]);
    rig.online(2).await;
    rig.enable_all(2).await;
    let mut events = rig.bus.events();
    rig.bus
        .disable(jointd::bus::Targets::Ids(vec![1]))
        .await
        .unwrap();
    rig.until("device 1 disabled by request", |s| {
        s.devices[&1].disabled_reason == Some(DisabledReason::Request)
    })
    .await;
    rig.bus.estop().await.unwrap();
    let mark = Instant::now();
    rig.until("both polled ready since", |s| {
        s.devices.values().all(|d| {
            d.info01
                .is_some_and(|(i, at)| at > mark && i.fsm == fsm::READY)
        })
    })
    .await;
    while let Ok(ev) = events.try_recv() {
        assert!(!matches!(ev, BusEvent::DeviceReset { .. }), "{ev:?}");
    }
    let snap = rig.bus.snapshot();
    assert!(snap
        .devices
        .values()
        .all(|d| d.disabled_reason == Some(DisabledReason::Estop) && d.resets == 0));
}
