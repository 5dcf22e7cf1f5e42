//! Device ids: which ids the wire can address (SPEC §8), and id lists as
//! people write them: `3`, `1-8`, `1,3,5-7`.

/// Lowest and highest addressable device id (SPEC §8).
pub const MIN_DEVICE_ID: u8 = 0x01;
pub const MAX_DEVICE_ID: u8 = 0x9F;
/// The address every device answers to (control, jog, config writes).
pub const ALL_DEVICES: u8 = 0xFF;

/// True for an id a single device can carry (1..=159).
pub fn is_device_id(id: u8) -> bool {
    (MIN_DEVICE_ID..=MAX_DEVICE_ID).contains(&id)
}

/// True for a host→device address: one device or all of them.
pub fn is_address(id: u8) -> bool {
    is_device_id(id) || id == ALL_DEVICES
}

/// The ids of `spec`, each 1..=159, in the order written (duplicates kept:
/// the simulator uses them to reproduce id conflicts).
pub fn parse_id_list(spec: &str) -> Result<Vec<u8>, String> {
    let mut ids = Vec::new();
    for part in spec.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        match part.split_once('-') {
            Some((a, b)) => {
                let (lo, hi) = (one(a)?, one(b)?);
                if lo > hi {
                    return Err(format!("range {part} runs backwards"));
                }
                ids.extend(lo..=hi);
            }
            None => ids.push(one(part)?),
        }
    }
    if ids.is_empty() {
        return Err(format!("`{spec}` names no device"));
    }
    Ok(ids)
}

fn one(text: &str) -> Result<u8, String> {
    let text = text.trim();
    match text.parse::<u8>() {
        Ok(id) if is_device_id(id) => Ok(id),
        _ => Err(format!("`{text}` is not a device id (1..=159)")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_and_ranges_parse_and_bad_ones_say_why() {
        assert_eq!(parse_id_list("1,3-4,3").unwrap(), vec![1, 3, 4, 3]);
        assert!(parse_id_list("0").unwrap_err().contains("not a device id"));
        assert!(parse_id_list("5-2").unwrap_err().contains("backwards"));
        assert!(parse_id_list(" , ")
            .unwrap_err()
            .contains("names no device"));
    }
}
