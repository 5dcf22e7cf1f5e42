//! A scripted bus owner for API tests that need exact control of what the
//! bus answers (a device that never answers, a bus that is down, a verify
//! mismatch). It consumes the same `Request`s the real owner does and
//! publishes snapshots through the same `BusShared`.
#![allow(dead_code)]

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use jointd::bus::authority::{Epoch, MotionAuthority, Revoked};
use jointd::bus::error::BusError;
use jointd::bus::handle::{
    BusShared, DeviceState, EstopReport, LinkState, Request, WriteOutcome, REQUEST_QUEUE_LEN,
};
use jointd::bus::{BusHandle, BusSnapshot, Targets};
use jointd::protocol::status::fsm;
use jointd::protocol::{
    CtrlMode, Gains, Info01, Info04, Info05, Info06, InfoBlock, Reply, ReplyBody,
};

/// How often the fake looks at the e-stop flag while idle.
const TICK: Duration = Duration::from_millis(1);

#[derive(Default)]
pub struct Script {
    /// Devices that never answer (reads time out: 504).
    pub silent: BTreeSet<u8>,
    /// The bus is down: every request fails with 503.
    pub down: bool,
    /// Writes read back another value (502).
    pub mismatch: bool,
    /// Config indices whose writes read back another value (502).
    pub mismatch_at: BTreeSet<u8>,
    /// Config indices whose writes go out but stay unconfirmed (504
    /// `write-unverified`); 13 is the flash write.
    pub unverified_at: BTreeSet<u8>,
    /// The device answers every read with INFO_07 and a flash write with
    /// another block than RES, as a confused or misaddressed device would
    /// (502 wherever it shows).
    pub wrong_block: bool,
    /// INFO_04 reads answer these max_current values in turn (then the
    /// default), whatever was written: a limit that does not read back.
    pub info04_max_current: VecDeque<u16>,
    /// Each request takes this long (to hold the queue busy for e-stop tests).
    pub delay: Duration,
    /// Requests served, by kind, in order.
    pub log: Vec<&'static str>,
}

pub struct FakeBus {
    pub handle: BusHandle,
    pub script: Arc<Mutex<Script>>,
}

struct Owner {
    shared: Arc<BusShared>,
    script: Arc<Mutex<Script>>,
    devices: BTreeMap<u8, DeviceState>,
    estop_seen: u64,
}

fn info01(fsm_state: u8) -> Info01 {
    Info01 {
        fsm: fsm_state,
        err_code: 0,
        soft_ver: 128,
        temp_raw: 80,
        angle: 0,
        vbus: 12 * 128,
    }
}

impl FakeBus {
    pub fn new(name: &str, ids: &[u8]) -> Self {
        let now = Instant::now();
        let devices: BTreeMap<u8, DeviceState> = ids
            .iter()
            .map(|&id| {
                let dev = DeviceState {
                    dev_id: id,
                    online: true,
                    info01: Some((info01(fsm::READY), now)),
                    mode: Some(CtrlMode::Position),
                    ..Default::default()
                };
                (id, dev)
            })
            .collect();
        let mut snap = BusSnapshot::new(name, "/dev/fake", 500_000);
        snap.link = LinkState::Up;
        snap.devices = devices.clone();
        let shared = BusShared::new(name.into(), snap);
        for (id, dev) in &devices {
            shared.setpoints.authority().mode_set(*id, dev.mode);
        }
        let (tx, rx) = sync_channel(REQUEST_QUEUE_LEN);
        let script = Arc::new(Mutex::new(Script::default()));
        let mut owner = Owner {
            shared: shared.clone(),
            script: script.clone(),
            devices,
            estop_seen: 0,
        };
        std::thread::spawn(move || owner.run(rx));
        Self {
            handle: BusHandle::new(shared, tx),
            script,
        }
    }

    pub fn script(&self) -> std::sync::MutexGuard<'_, Script> {
        self.script.lock().unwrap()
    }
}

impl Owner {
    fn run(&mut self, rx: Receiver<Request>) {
        loop {
            self.check_estop();
            match rx.recv_timeout(TICK) {
                Ok(req) => {
                    let delay = self.script.lock().unwrap().delay;
                    std::thread::sleep(delay); // models a slow wire, not a test wait
                    if self.check_estop() {
                        fail(req, BusError::Preempted);
                        while let Ok(r) = rx.try_recv() {
                            fail(r, BusError::Preempted);
                        }
                        continue;
                    }
                    self.serve(req);
                    self.publish();
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return,
            }
        }
    }

    /// Handles a pending e-stop; true if one was handled.
    fn check_estop(&mut self) -> bool {
        let generation = self
            .shared
            .estop_generation
            .load(std::sync::atomic::Ordering::SeqCst);
        if generation <= self.estop_seen {
            return false;
        }
        self.estop_seen = generation;
        for dev in self.devices.values_mut() {
            dev.info01 = Some((info01(fsm::READY), Instant::now()));
        }
        self.shared.setpoints.clear(None);
        self.script.lock().unwrap().log.push("estop");
        let report = EstopReport {
            bus: self.shared.name.clone(),
            frames_sent: 1 + self.devices.len() as u32,
            preempted_requests: 0,
            latency_us: 10,
            // The fake's devices read back ready, as set above.
            confirmed: self.devices.keys().copied().collect(),
            ..EstopReport::default()
        };
        self.publish();
        self.shared
            .estop_done
            .send_replace((generation, Some(Ok(report))));
        true
    }

    fn publish(&self) {
        let mut snap = (**self.shared.snapshot.borrow()).clone();
        snap.devices = self.devices.clone();
        snap.published_at = Instant::now();
        self.shared.snapshot.send_replace(Arc::new(snap));
    }

    fn ids(&self, targets: &Targets) -> Vec<u8> {
        match targets {
            Targets::All => self.devices.keys().copied().collect(),
            Targets::Ids(ids) => ids.clone(),
        }
    }

    fn authority(&self) -> &MotionAuthority {
        self.shared.setpoints.authority()
    }

    fn set_fsm(&mut self, targets: &Targets, state: u8) -> Result<(), BusError> {
        for id in self.ids(targets) {
            let dev = self.known(id)?;
            dev.info01 = Some((info01(state), Instant::now()));
        }
        Ok(())
    }

    fn known(&mut self, id: u8) -> Result<&mut DeviceState, BusError> {
        let name = self.shared.name.clone();
        self.devices.get_mut(&id).ok_or(BusError::UnknownDevice {
            bus: name,
            dev_id: id,
        })
    }

    fn gate(&self, id: Option<u8>) -> Result<(), BusError> {
        let s = self.script.lock().unwrap();
        if s.down {
            return Err(BusError::Down {
                bus: self.shared.name.clone(),
                reason: "unplugged".into(),
            });
        }
        match id {
            Some(id) if s.silent.contains(&id) => Err(BusError::Timeout {
                dev_id: id,
                what: "request".into(),
                attempts: 3,
                timeout_us: 2000,
            }),
            _ => Ok(()),
        }
    }

    fn serve(&mut self, req: Request) {
        let kind = kind(&req);
        self.script.lock().unwrap().log.push(kind);
        match req {
            Request::Enable { targets, reply } => {
                // As the real owner: a new epoch, taking commands once enabled.
                let epochs: Vec<(u8, Epoch)> = self
                    .ids(&targets)
                    .into_iter()
                    .map(|id| (id, self.authority().revoke(id, Revoked::Reenabled)))
                    .collect();
                let r = self
                    .gate(None)
                    .and_then(|_| self.set_fsm(&targets, fsm::RUN));
                if r.is_ok() {
                    for (id, epoch) in epochs {
                        self.authority().arm(id, epoch);
                    }
                }
                let _ = reply.send(r);
            }
            Request::Disable { targets, reply } => {
                for id in self.ids(&targets) {
                    self.authority().revoke(id, Revoked::Disabled);
                }
                let r = self
                    .gate(None)
                    .and_then(|_| self.set_fsm(&targets, fsm::READY));
                let _ = reply.send(r);
            }
            Request::Jog { dev_id, reply, .. } => {
                let _ = reply.send(self.gate(Some(dev_id)));
            }
            Request::Rezero { dev_id, reply } => {
                let _ = reply.send(self.gate(Some(dev_id)));
            }
            Request::SetMode {
                dev_id,
                mode,
                reply,
            } => {
                let r = self.gate(Some(dev_id)).and_then(|_| {
                    self.known(dev_id)?.mode = Some(mode);
                    Ok(())
                });
                let settled = if r.is_ok() { Some(mode) } else { None };
                let known = self.devices.get(&dev_id).and_then(|d| d.mode);
                self.authority().mode_set(dev_id, settled.or(known));
                let _ = reply.send(r);
            }
            Request::ReadInfo {
                dev_id,
                block,
                reply,
            } => {
                let r = self
                    .gate(Some(dev_id))
                    .and_then(|_| self.read(dev_id, block));
                let _ = reply.send(r);
            }
            Request::WriteConfig {
                dev_id,
                param,
                reply,
            } => {
                let (index, value) = param.index_value();
                let (mismatch, unverified) = {
                    let s = self.script.lock().unwrap();
                    (
                        s.mismatch || s.mismatch_at.contains(&index),
                        s.unverified_at.contains(&index),
                    )
                };
                let outcome = if unverified {
                    Err(unverified_write(dev_id, index, value))
                } else if mismatch {
                    Err(BusError::VerifyMismatch {
                        dev_id,
                        index,
                        expected: value,
                        found: 0,
                    })
                } else {
                    Ok(WriteOutcome {
                        dev_id,
                        index,
                        value,
                        verified_by: "read_back",
                    })
                };
                let r = self.gate(Some(dev_id)).and(outcome);
                let _ = reply.send(r);
            }
            Request::WriteAll { ids, param, reply } => {
                let (index, value) = param.index_value();
                let per_device = ids
                    .into_iter()
                    .map(|dev_id| {
                        let outcome = WriteOutcome {
                            dev_id,
                            index,
                            value,
                            verified_by: "read_back",
                        };
                        (dev_id, self.gate(Some(dev_id)).map(|_| outcome))
                    })
                    .collect();
                let r = Ok(jointd::bus::handle::WriteAllOutcome {
                    one_frame: false,
                    per_device,
                });
                let _ = reply.send(r);
            }
            Request::WriteFlash { dev_id, reply } => {
                if self.script.lock().unwrap().wrong_block {
                    // What the real owner's RES check reports.
                    let what = format!("device {dev_id} answered the flash write with INFO_07");
                    let _ = reply.send(Err(BusError::UnexpectedReply(what)));
                    return;
                }
                let unverified = self.script.lock().unwrap().unverified_at.contains(&13);
                let r = self.gate(Some(dev_id)).and_then(|_| match unverified {
                    true => Err(unverified_write(dev_id, 13, 0xA5)),
                    false => Ok(WriteOutcome {
                        dev_id,
                        index: 13,
                        value: 0xA5,
                        verified_by: "res",
                    }),
                });
                let _ = reply.send(r);
            }
            Request::SetId {
                dev_id,
                new_id,
                reply,
            } => {
                let r = self.gate(Some(dev_id)).and_then(|_| {
                    let mut dev = self.devices.remove(&dev_id).ok_or(BusError::Stopped)?;
                    dev.dev_id = new_id;
                    self.devices.insert(new_id, dev);
                    Ok(WriteOutcome {
                        dev_id: new_id,
                        index: 4,
                        value: u16::from(new_id) << 7,
                        verified_by: "res",
                    })
                });
                let _ = reply.send(r);
            }
            Request::SetBaud { baud, reply } => {
                let r = self.gate(None).map(|_| {
                    let mut snap = (**self.shared.snapshot.borrow()).clone();
                    snap.baud = baud;
                    self.shared.snapshot.send_replace(Arc::new(snap));
                });
                let _ = reply.send(r);
            }
            Request::Scan { first, last, reply } => {
                let r = self.gate(None).map(|_| {
                    self.devices
                        .keys()
                        .copied()
                        .filter(|id| (first..=last).contains(id))
                        .collect()
                });
                let _ = reply.send(r);
            }
            // A scripted bus has no port to lend.
            Request::LendPort { reply, .. } => {
                let _ = reply.send(Err(BusError::WrongState(
                    "a scripted bus has no port".into(),
                )));
            }
        }
    }

    fn read(&mut self, id: u8, block: InfoBlock) -> Result<Reply, BusError> {
        let wrong_block = self.script.lock().unwrap().wrong_block;
        let max_current = match block {
            InfoBlock::Info04 => self.script.lock().unwrap().info04_max_current.pop_front(),
            _ => None,
        };
        let dev = self.known(id)?;
        let block = if wrong_block {
            InfoBlock::Info07
        } else {
            block
        };
        let body = match block {
            InfoBlock::Info01 => ReplyBody::Info01(dev.info01.map(|(i, _)| i).unwrap_or_default()),
            InfoBlock::Info02 => ReplyBody::Info02(Default::default()),
            InfoBlock::Info03 => ReplyBody::Info03(Gains {
                pos_kp: 4095,
                pos_kd: 0,
                spd_kp: 4096,
                spd_ki: 256,
            }),
            InfoBlock::Info04 => ReplyBody::Info04(Info04 {
                lpf_level: 2,
                baud_level: 0,
                param_ver: 3,
                reserved: 0,
                max_current: max_current.unwrap_or(4368),
                protect_limit: 873,
            }),
            InfoBlock::Info05 => ReplyBody::Info05(Info05 {
                protect_cur_lv1: 2912,
                protect_delay_lv1_ms: 600,
                recv_cur: 582,
                recover_delay_ms: 400,
            }),
            InfoBlock::Info06 => ReplyBody::Info06(Info06 {
                cold_dt: 4,
                plus_t: 2,
                extra: [0; 6],
            }),
            InfoBlock::Info07 => ReplyBody::Info07([0; 8]),
        };
        Ok(Reply::new(id, body))
    }
}

fn kind(req: &Request) -> &'static str {
    match req {
        Request::Enable { .. } => "enable",
        Request::Disable { .. } => "disable",
        Request::Jog { .. } => "jog",
        Request::Rezero { .. } => "rezero",
        Request::SetMode { .. } => "set_mode",
        Request::ReadInfo { .. } => "read_info",
        Request::WriteConfig { .. } => "write_config",
        Request::WriteAll { .. } => "write_all",
        Request::WriteFlash { .. } => "write_flash",
        Request::SetId { .. } => "set_id",
        Request::SetBaud { .. } => "set_baud",
        Request::Scan { .. } => "scan",
        Request::LendPort { .. } => "lend_port",
    }
}

fn fail(req: Request, err: BusError) {
    match req {
        Request::Enable { reply, .. } | Request::Disable { reply, .. } => {
            drop(reply.send(Err(err)))
        }
        Request::Jog { reply, .. }
        | Request::Rezero { reply, .. }
        | Request::SetMode { reply, .. } => drop(reply.send(Err(err))),
        Request::SetBaud { reply, .. } => drop(reply.send(Err(err))),
        Request::ReadInfo { reply, .. } => drop(reply.send(Err(err))),
        Request::WriteConfig { reply, .. }
        | Request::WriteFlash { reply, .. }
        | Request::SetId { reply, .. } => drop(reply.send(Err(err))),
        Request::Scan { reply, .. } => drop(reply.send(Err(err))),
        Request::WriteAll { reply, .. } => drop(reply.send(Err(err))),
        Request::LendPort { reply, .. } => drop(reply.send(Err(err))),
    }
}

/// What the real owner reports of a write whose confirmation was lost.
fn unverified_write(dev_id: u8, index: u8, value: u16) -> BusError {
    BusError::Unverified {
        dev_id,
        index,
        value,
        what: format!("write index {index} = {value}"),
        reason: "no read-back answered after 3 send(s)".into(),
    }
}
