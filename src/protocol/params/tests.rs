//! The table's own tests: every row consistent, and a fictitious row (added
//! to [`PARAMS`] in test builds only) picked up by every user of the table.

use std::collections::HashSet;

use super::*;

/// A row no SPEC has: index 40, an 8-bit level shown in INFO_04's reserved
/// byte. Only this constant and the `#[cfg(test)]` line in [`PARAMS`] add it;
/// the tests below find it in the decoder and the frame JSON, and the
/// crate's `params_reach` tests in the REST schema, the write verification
/// and the simulator.
pub(crate) const FICTITIOUS: ParamRow = ParamRow {
    index: 40,
    name: "TEST_LEVEL",
    key: "test_level",
    access: Access::Write,
    raw: RawType::U8,
    scale: Scale::Plain,
    range: (0, 9),
    reply: ReplyKind::None,
    read_back: Some(Field {
        block: InfoBlock::Info04,
        at: 3,
        width: RawType::U8,
    }),
    storage: Storage::Ram,
    guard: Guard::None,
    api: true,
    default: 0,
    since: Revision::V2_0_8,
    doc: "A level that exists only in test builds",
};

#[test]
fn indices_names_and_keys_are_unique() {
    let mut indices = HashSet::new();
    let mut names = HashSet::new();
    let mut keys = HashSet::new();
    for r in PARAMS {
        assert!(indices.insert(r.index), "index {} twice", r.index);
        assert!(names.insert(r.name), "name {} twice", r.name);
        assert!(keys.insert(r.key), "key {} twice", r.key);
    }
}

#[test]
fn ranges_fit_the_raw_type_and_defaults_the_range() {
    for r in PARAMS {
        let (min, max) = r.range;
        assert!(min <= max, "{}", r.name);
        assert!(
            max <= r.raw.max(),
            "{}: {max} does not fit {:?}",
            r.name,
            r.raw
        );
        if r.is_setting() {
            assert!((min..=max).contains(&r.default), "{}", r.name);
        }
    }
}

#[test]
fn scale_round_trips_at_both_ends_of_every_range() {
    for r in PARAMS.iter().filter(|r| r.raw != RawType::None) {
        if r.scale == Scale::BaudLevel {
            continue; // levels map to bauds one by one, checked below
        }
        for raw in [r.range.0, r.range.1, r.default.clamp(r.range.0, r.range.1)] {
            let back = r.to_raw(r.physical(raw));
            assert_eq!(back, Ok(raw), "{} raw {raw}", r.name);
        }
        let (lo, hi) = r.physical_range();
        assert!(r.to_raw(hi + 1.0).is_err(), "{} above {hi}", r.name);
        assert!(r.to_raw(lo - 1.0).is_err(), "{} below {lo}", r.name);
    }
    let baud = by_index(index::BAUD_RATE).expect("baud row");
    for level in BaudLevel::ALL {
        assert_eq!(baud.to_raw(baud.physical(level as u16)), Ok(level as u16));
    }
}

#[test]
fn reads_and_info_blocks_agree() {
    for r in PARAMS {
        assert_eq!(
            r.access == Access::Read,
            r.info_block().is_some(),
            "{}",
            r.name
        );
        assert_eq!(
            r.access == Access::Read,
            r.reply == ReplyKind::Info,
            "{}",
            r.name
        );
    }
    for block in InfoBlock::ALL {
        let row = by_index(block.index()).expect("every INFO block has a row");
        assert_eq!(row.info_block(), Some(block));
    }
}

#[test]
fn read_back_fields_sit_inside_their_block_without_overlap() {
    let mut used = HashSet::new();
    for r in PARAMS {
        let Some(f) = r.read_back else { continue };
        let width = if f.width == RawType::U16 { 2 } else { 1 };
        assert_ne!(f.width, RawType::None, "{}", r.name);
        assert!(f.at + width <= 8, "{}", r.name);
        assert!(
            r.raw.max() <= f.width.max(),
            "{}: field narrower than value",
            r.name
        );
        for byte in f.at..f.at + width {
            assert!(
                used.insert((f.block, byte)),
                "{}: byte {byte} taken",
                r.name
            );
        }
        let mut d = [0u8; 8];
        f.write(&mut d, r.range.1);
        assert_eq!(f.read(&d), r.range.1, "{}", r.name);
    }
}

#[test]
fn api_rows_are_verifiable_ram_settings() {
    for r in api_rows() {
        assert!(r.is_setting(), "{}", r.name);
        // Rev 2.0.8's settings have no published read-back: offered to
        // 2.0.8 devices as write-only, their writes reported unverifiable.
        assert!(
            r.read_back.is_some() || r.since == Revision::V2_0_8,
            "{}: a REST write must be verifiable",
            r.name
        );
        assert_eq!(r.guard, Guard::None, "{}", r.name);
    }
}

#[test]
fn spec_rows_carry_their_revision() {
    assert_eq!(name_of(index::INFO_07_R), "INFO_07_R");
    assert_eq!(
        by_name("CONFIG_INFO_07_R").map(|r| r.since),
        Some(Revision::V2_0_8)
    );
    assert_eq!(by_name("buad_rate").map(|r| r.index), Some(15));
    assert_eq!(by_key("max_current_a").map(|r| r.index), Some(18));
    for idx in [index::DRV_OT, index::SPD_LIMIT, index::SN, index::INFO_07_R] {
        assert_eq!(by_index(idx).map(|r| r.since), Some(Revision::V2_0_8));
    }
    assert_eq!(name_of(29), "UNKNOWN");
    let spec_rows = PARAMS
        .iter()
        .filter(|r| r.index != FICTITIOUS.index)
        .count();
    assert_eq!(spec_rows, 32, "SPEC §4.3 lists indices 0..=28 and 30..=32");
}

// ---- the fictitious row, seen by every user of the table ----

#[test]
fn fictitious_row_is_decoded_and_shown_as_json() {
    use crate::protocol::frame_json::{command_from_json, frame_to_json};
    use serde_json::json;
    let described = json!({"kind": "config", "dev_id": 3, "index": 40, "value": 7});
    let cmd = command_from_json(&described).expect("encodes");
    let decoded = frame_to_json(&cmd.to_frame());
    assert_eq!(decoded["name"], "TEST_LEVEL");
    assert_eq!(decoded["value"], 7);
    let too_high = json!({"kind": "config", "dev_id": 3, "index": 40, "value": 10});
    assert!(
        command_from_json(&too_high).is_err(),
        "the row's range 0..=9 holds"
    );
}

#[test]
fn read_back_fields_agree_with_the_typed_info_blocks() {
    use crate::protocol::reply::{Gains, Info04, Info05, Info06};
    let mut blocks = [[0u8; 8]; 4];
    let order = [B::Info03, B::Info04, B::Info05, B::Info06];
    // A distinct value per row, small enough for an 8-bit field.
    let value = |r: &ParamRow| u16::from(r.index) + 1;
    for (slot, block) in order.iter().enumerate() {
        for (row, field) in fields_of(*block) {
            field.write(&mut blocks[slot], value(row));
        }
    }
    let g = Gains::from_bytes(&blocks[0]);
    let i4 = Info04::from_bytes(&blocks[1]);
    let i5 = Info05::from_bytes(&blocks[2]);
    let i6 = Info06::from_bytes(&blocks[3]);
    let typed = [
        (index::SET_POS_KP, g.pos_kp),
        (index::SET_POS_KD, g.pos_kd),
        (index::SET_SPD_KP, g.spd_kp),
        (index::SET_SPD_KI, g.spd_ki),
        (index::POS_LPF_LV, i4.lpf_level.into()),
        (index::BAUD_RATE, i4.baud_level.into()),
        (index::MAX_CUR, i4.max_current),
        (index::PROTECT_CUR_LIMIT, i4.protect_limit),
        (index::PROTECT_CUR_LV1, i5.protect_cur_lv1),
        (index::CUR_LV1_DELAY, i5.protect_delay_lv1_ms),
        (index::RECV_CUR, i5.recv_cur),
        (index::CUR_RECV_WIN, i5.recover_delay_ms),
        (index::COLD_TIME, i6.cold_dt.into()),
        (index::PLUS_TIME, i6.plus_t.into()),
    ];
    for (idx, got) in typed {
        assert_eq!(got, u16::from(idx) + 1, "{}", name_of(idx));
    }
}

#[test]
fn revisions_parse_and_print_as_the_spec_names_them() {
    for r in Revision::ALL {
        assert_eq!(Revision::parse(&r.to_string()), Ok(r));
    }
    assert_eq!("v2.0.8".parse::<Revision>(), Ok(Revision::V2_0_8));
    assert_eq!(Revision::parse(" 2.0.1 "), Ok(Revision::V2_0_1));
    for bad in ["", "2.0", "2.0.2", "208", "latest"] {
        assert!(Revision::parse(bad).is_err(), "{bad:?}");
    }
    assert!(
        Revision::V2_0_1 < Revision::V2_0_8,
        "rows compare `since` by order"
    );
}
