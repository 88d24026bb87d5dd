"""Synthetic participants (issue 22): placement is learnt more slowly than motion, and clumsy hands
now and then take a bite too near the edge."""

import numpy as np
import pytest
from scipy.stats import binomtest

from sessions.synthetic import (
    PLACEMENT_LEARNING,
    SHALLOW_BITE_OFFSET,
    Profile,
    in_restricted_access,
    pass_parameters,
)


def test_placement_skill_follows_the_same_curve_at_a_fraction_of_the_rate():
    trainee = Profile("trainee", 0.2, 0.8)
    assert trainee.placement_skill(1) == trainee.skill(1) == pytest.approx(0.2)
    slower = Profile("trainee", 0.2, 0.8 * PLACEMENT_LEARNING)
    for trial in (2, 4, 6):
        assert trainee.placement_skill(trial) == pytest.approx(slower.skill(trial), rel=1e-12)
        assert trainee.placement_skill(trial) < trainee.skill(trial)
    expert = Profile("expert", 0.9, 0.0)
    assert expert.placement_skill(5) == expert.skill(5) == 0.9


@pytest.mark.parametrize(("placement", "rate"), [(0.0, 0.3), (0.5, 0.15), (1.0, 0.0)])
def test_shallow_bites_come_at_the_stated_rate(placement, rate):
    """0.3 x placement clumsiness of a hand's passes are bites taken too near the edge (binomial test
    over 2000 seeds); the motion parameters of a seed do not depend on where the bite lands."""
    shallow = sum(
        pass_parameters(0.5, seed, placement).entry_offset == SHALLOW_BITE_OFFSET for seed in range(2000)
    )
    if rate == 0.0:
        assert shallow == 0
    else:
        assert binomtest(shallow, 2000, rate).pvalue > 0.001, shallow
    a, b = pass_parameters(0.5, 11, 0.1), pass_parameters(0.5, 11, 0.9)
    assert (a.entry_angle_deg, a.insertion_speed, a.hesitations) == (
        b.entry_angle_deg,
        b.insertion_speed,
        b.hesitations,
    )


def test_restricted_access_magnifies_what_a_hand_gets_wrong():
    hand = pass_parameters(0.4, 3)
    restricted = in_restricted_access(hand, 45.0)
    factor = 1 + np.sin(np.radians(45.0))
    assert restricted.entry_angle_deg == pytest.approx(hand.entry_angle_deg * factor)
    assert 1 - restricted.wrist_rotation == pytest.approx((1 - hand.wrist_rotation) * factor)
    assert in_restricted_access(hand, 0.0) == hand
