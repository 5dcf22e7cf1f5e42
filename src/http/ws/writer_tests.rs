use super::*;

#[test]
fn a_close_reason_is_cut_to_fit_on_a_character_boundary() {
    assert_eq!(fit_close_reason("too slow"), "too slow");
    // 62 two-byte characters, 124 bytes: cut to 61 of them.
    let long = "é".repeat(62);
    let cut = fit_close_reason(&long);
    assert_eq!(cut.len(), 122);
    assert!(long.starts_with(cut));
    assert_eq!(fit_close_reason(&"a".repeat(200)).len(), MAX_CLOSE_REASON);
}
