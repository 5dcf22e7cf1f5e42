"""What makes a joint's telemetry unusable, without a daemon."""

import pytest

from lerobot_robot_jointd.link import Sample, Stale, present

JOINTS = [("index", "sim0", 3)]


def sample(online=True, age_ms=5.0, taken_at=100.0, angle=12.0):
    return Sample({"online": online, "angle_deg": angle}, age_ms, taken_at)


def test_a_fresh_sample_with_an_angle_is_present():
    got = present({("sim0", 3): sample()}, JOINTS, now=100.2, stale_s=1.0, whose="hand h")
    assert got["index"]["angle_deg"] == 12.0


@pytest.mark.parametrize("latest, why", [
    ({}, "never seen"),
    ({("sim0", 3): sample(online=False)}, "offline"),
    ({("sim0", 3): sample(angle=None)}, "no angle"),
    # 5 ms old when sent, taken 1 s ago: 1005 ms old now.
    ({("sim0", 3): sample(taken_at=99.2)}, "its newest sample is 1005 ms old"),
])
def test_a_joint_unseen_offline_angleless_or_old_is_stale(latest, why):
    with pytest.raises(Stale, match=f"joint index \\(sim0/3\\) of hand h: {why}"):
        present(latest, JOINTS, now=100.2, stale_s=1.0, whose="hand h")
