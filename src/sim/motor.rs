//! The modelled motor's constants that both the joint's physics and the
//! objects it presses need.

/// Current to hold position at rest, A: what a joint draws before any of
/// its current pushes on anything.
pub(crate) const HOLD_CURRENT_A: f64 = 0.03;
