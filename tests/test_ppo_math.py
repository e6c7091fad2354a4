"""PPO's hand-checkable pieces against numbers worked out by hand (and scipy for the Gaussian).

gamma = lam = 0.5 below so that every intermediate value is a short binary fraction and the
expected numbers are exact in float32.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate, stats

from hintsjax.algorithms.ppo_math import (
    clipped_surrogate_loss,
    gae,
    gaussian_entropy,
    gaussian_log_prob,
    squashed_entropy,
)

GAMMA, LAM = 0.5, 0.5  # gamma * lam = 0.25

# [T=4, N=2]. Column 0 terminates at t=1 and then runs on to last_value; column 1 is truncated
# at t=2 (final_value 6) and then runs on to last_value. final_value is 9 wherever it must be
# ignored (no truncation there), so using it by mistake shows.
REWARD = np.array([[1, 0], [0, 1], [2, 1], [1, 2]], np.float32)
VALUE = np.array([[1, 2], [2, 1], [0, 2], [1, 0]], np.float32)
TERMINATED = np.array([[0, 0], [1, 0], [0, 0], [0, 0]], bool)
TRUNCATED = np.array([[0, 0], [0, 0], [0, 1], [0, 0]], bool)
FINAL_VALUE = np.array([[9, 9], [9, 9], [9, 6], [9, 9]], np.float32)
LAST_VALUE = np.array([4, -2], np.float32)

# Column 0: next values (v[t+1], 0 after the termination, last_value at the end) = [2, 0, 1, 4]
#   delta_t = r_t + gamma * next_t - v_t
#   delta_0 = 1 + 0.5*2 - 1 = 1
#   delta_1 = 0 + 0.5*0 - 2 = -2     (terminated: bootstrap 0)
#   delta_2 = 2 + 0.5*1 - 0 = 2.5
#   delta_3 = 1 + 0.5*4 - 1 = 2      (bootstraps from last_value = 4)
#   A_3 = 2
#   A_2 = 2.5 + 0.25*2 = 3
#   A_1 = -2                          (nothing flows back across the termination)
#   A_0 = 1 + 0.25*(-2) = 0.5
#   targets = A + v = [1.5, 0, 3, 3]
# Column 1: next values = [1, 2, 6 (final_value: truncated), -2 (last_value)]
#   delta_0 = 0 + 0.5*1 - 2 = -1.5
#   delta_1 = 1 + 0.5*2 - 1 = 1
#   delta_2 = 1 + 0.5*6 - 2 = 2       (truncated: bootstrap from final_value = 6, not v_3 = 0)
#   delta_3 = 2 + 0.5*(-2) - 0 = 1
#   A_3 = 1
#   A_2 = 2                           (nothing flows back across the truncation)
#   A_1 = 1 + 0.25*2 = 1.5
#   A_0 = -1.5 + 0.25*1.5 = -1.125
#   targets = A + v = [0.875, 2.5, 4, 1]
EXPECTED_ADVANTAGE = np.array([[0.5, -1.125], [-2, 1.5], [3, 2], [2, 1]], np.float32)
EXPECTED_TARGET = np.array([[1.5, 0.875], [0, 2.5], [3, 4], [3, 1]], np.float32)


def run_gae(terminated=TERMINATED, truncated=TRUNCATED):
    advantage, target = gae(
        jnp.asarray(REWARD),
        jnp.asarray(VALUE),
        jnp.asarray(terminated),
        jnp.asarray(truncated),
        jnp.asarray(FINAL_VALUE),
        jnp.asarray(LAST_VALUE),
        GAMMA,
        LAM,
    )
    return np.asarray(advantage), np.asarray(target)


def test_gae_matches_hand_computation():
    advantage, target = run_gae()
    assert advantage.shape == target.shape == (4, 2)
    np.testing.assert_allclose(advantage, EXPECTED_ADVANTAGE, rtol=0, atol=1e-6)
    np.testing.assert_allclose(target, EXPECTED_TARGET, rtol=0, atol=1e-6)
    np.testing.assert_allclose(target, advantage + VALUE, rtol=0, atol=1e-6)


def test_gae_is_jittable_and_agrees():
    advantage, target = jax.jit(gae, static_argnums=(6, 7))(
        REWARD, VALUE, TERMINATED, TRUNCATED, FINAL_VALUE, LAST_VALUE, GAMMA, LAM
    )
    np.testing.assert_allclose(np.asarray(advantage), EXPECTED_ADVANTAGE, rtol=0, atol=1e-6)
    np.testing.assert_allclose(np.asarray(target), EXPECTED_TARGET, rtol=0, atol=1e-6)


def test_truncation_differs_from_termination_by_the_bootstrap():
    # Same data, but column 1's episode ends at t=2 by termination instead of truncation:
    # delta_2 = 1 + 0 - 2 = -1 instead of 2, a change of gamma * final_value = 0.5 * 6 = 3.
    terminated = TERMINATED.copy()
    truncated = TRUNCATED.copy()
    terminated[2, 1], truncated[2, 1] = True, False
    adv_trunc, _ = run_gae()
    adv_term, tgt_term = run_gae(terminated, truncated)
    diff = adv_trunc - adv_term
    bootstrap = GAMMA * FINAL_VALUE[2, 1]
    assert bootstrap == 3.0
    np.testing.assert_allclose(diff[2, 1], bootstrap, rtol=0, atol=1e-6)
    # Later steps of that column and the whole other column are untouched ...
    np.testing.assert_array_equal(diff[3, 1], 0.0)
    np.testing.assert_array_equal(diff[:, 0], 0.0)
    # ... and earlier steps see the change discounted by (gamma * lam) per step back.
    np.testing.assert_allclose(diff[1, 1], GAMMA * LAM * bootstrap, rtol=0, atol=1e-6)
    np.testing.assert_allclose(diff[0, 1], (GAMMA * LAM) ** 2 * bootstrap, rtol=0, atol=1e-6)
    # target = A + v = -1 + 2
    np.testing.assert_allclose(tgt_term[2, 1], -1.0 + 2.0, rtol=0, atol=1e-6)


def test_gae_termination_wins_over_truncation():
    # Both flags set (the core env never does this, but a wrapper might): bootstrap 0.
    terminated = TERMINATED.copy()
    terminated[2, 1] = True
    adv_both, _ = run_gae(terminated, TRUNCATED)
    np.testing.assert_allclose(adv_both[2, 1], 1.0 + 0.0 - 2.0, rtol=0, atol=1e-6)


def test_gae_segments_cut_the_advantage_but_keep_the_bootstrap():
    # segment=2 cuts after rows 1 and 3 (Brax's unrolls of 2 steps). Column 0 already ends at row 1
    # (terminated) and row 3 is the rollout's end: unchanged. Column 1 is cut after row 1: A_1 is
    # its own delta, 1 (bootstrapped from v_2 = 2 as before), not 1.5, and A_0 = -1.5 + 0.25 * 1.
    advantage, target = gae(
        REWARD, VALUE, TERMINATED, TRUNCATED, FINAL_VALUE, LAST_VALUE, GAMMA, LAM, segment=2
    )
    expected = EXPECTED_ADVANTAGE.copy()
    expected[1, 1], expected[0, 1] = 1.0, -1.25
    np.testing.assert_allclose(np.asarray(advantage), expected, rtol=0, atol=1e-6)
    np.testing.assert_allclose(np.asarray(target), expected + VALUE, rtol=0, atol=1e-6)
    whole, _ = gae(
        REWARD, VALUE, TERMINATED, TRUNCATED, FINAL_VALUE, LAST_VALUE, GAMMA, LAM, segment=4
    )
    # one segment: GAE as before
    np.testing.assert_allclose(np.asarray(whole), EXPECTED_ADVANTAGE, rtol=0, atol=1e-6)


def test_without_the_truncation_bootstrap_a_cut_step_teaches_nothing_as_in_brax():
    # bootstrap_truncated=False: column 1's truncated step (t=2) gets advantage 0, target v_2 = 2;
    # nothing flowed back across it anyway, so A_1 = delta_1 = 1 and A_0 = -1.5 + 0.25 * 1.
    advantage, target = gae(
        REWARD,
        VALUE,
        TERMINATED,
        TRUNCATED,
        FINAL_VALUE,
        LAST_VALUE,
        GAMMA,
        LAM,
        bootstrap_truncated=False,
    )
    expected = EXPECTED_ADVANTAGE.copy()
    expected[2, 1], expected[1, 1], expected[0, 1] = 0.0, 1.0, -1.25
    np.testing.assert_allclose(np.asarray(advantage), expected, rtol=0, atol=1e-6)
    np.testing.assert_allclose(np.asarray(target), expected + VALUE, rtol=0, atol=1e-6)
    # Brax 0.14.2's compute_gae (bootstrap_on_timeout off, its default): its value targets vs are
    # these targets (its advantages are another quantity, r + gamma vs_{t+1} - v_t)
    from brax.training.agents.ppo.losses import compute_gae

    vs, _ = compute_gae(
        jnp.asarray(TRUNCATED, jnp.float32),
        jnp.asarray(TERMINATED, jnp.float32),
        jnp.asarray(REWARD),
        jnp.asarray(VALUE),
        jnp.asarray(LAST_VALUE),
        LAM,
        GAMMA,
    )
    np.testing.assert_allclose(np.asarray(vs), np.asarray(target), rtol=0, atol=1e-6)


# -- clipped surrogate --------------------------------------------------------------------------

CLIP, VF, ENT = 0.2, 0.5, 0.01
# Ratios pi/pi_old and advantages, clip range [0.8, 1.2]; per-sample min(r A, clip(r) A):
#   r=1.1, A=+2: inside        min(2.2, 2.2)   =  2.2
#   r=1.5, A=+2: above, A>0    min(3.0, 2.4)   =  2.4   (clipped: no gain past 1+eps)
#   r=0.5, A=+1: below, A>0    min(0.5, 0.8)   =  0.5   (unclipped: the pessimistic bound)
#   r=1.5, A=-1: above, A<0    min(-1.5, -1.2) = -1.5   (unclipped)
#   r=0.5, A=-1: below, A<0    min(-0.5, -0.8) = -0.8   (clipped)
#   r=0.9, A=-2: inside        min(-1.8, -1.8) = -1.8
#   sum = 1.0, policy_loss = -1/6
RATIO = np.array([1.1, 1.5, 0.5, 1.5, 0.5, 0.9], np.float32)
ADVANTAGE = np.array([2, 2, 1, -1, -1, -2], np.float32)
CLIPPED = np.array([False, True, False, False, True, False])  # where the clipped term is the min
# value - target = [0, 2, 0, -1, 1, -2]: squares [0, 4, 0, 1, 1, 4], value_loss = 10/6 = 5/3
VALUE_PRED = np.array([1, 2, 3, 0, 0, 0], np.float32)
VALUE_TARGET = np.array([1, 0, 3, 1, -1, 2], np.float32)
OLD_LOG_PROB = np.full(6, -0.7, np.float32)


def surrogate(entropy=0.7, log_prob=None):
    log_prob = OLD_LOG_PROB + np.log(RATIO) if log_prob is None else log_prob
    return clipped_surrogate_loss(
        jnp.asarray(log_prob),
        OLD_LOG_PROB,
        ADVANTAGE,
        VALUE_PRED,
        VALUE_TARGET,
        jnp.float32(entropy),
        CLIP,
        VF,
        ENT,
    )


def test_clipped_surrogate_matches_hand_computation():
    loss, parts = surrogate()
    np.testing.assert_allclose(parts["policy_loss"], -1.0 / 6.0, rtol=1e-5)
    np.testing.assert_allclose(parts["value_loss"], 5.0 / 3.0, rtol=1e-6)
    np.testing.assert_allclose(parts["entropy"], 0.7, rtol=1e-6)
    # loss = policy + vf * value - ent * entropy = -1/6 + 0.5 * 5/3 - 0.01 * 0.7 = 2/3 - 0.007
    np.testing.assert_allclose(loss, 2.0 / 3.0 - 0.007, rtol=1e-5)
    # clip fraction: |r - 1| > 0.2 for r in {1.5, 0.5, 1.5, 0.5}: 4/6
    np.testing.assert_allclose(parts["clip_fraction"], 4.0 / 6.0, rtol=1e-6)
    # approx_kl = mean((r - 1) - ln r):
    #   1.1: 0.1 - 0.0953102 = 0.0046898;  1.5: 0.5 - 0.4054651 = 0.0945349 (twice)
    #   0.5: -0.5 + 0.6931472 = 0.1931472 (twice);  0.9: -0.1 + 0.1053605 = 0.0053605
    #   sum = 0.5854145, mean = 0.0975691
    np.testing.assert_allclose(parts["approx_kl"], 0.0975691, rtol=1e-4)
    assert set(parts) >= {"policy_loss", "value_loss", "entropy", "approx_kl", "clip_fraction"}


def test_clipped_surrogate_entropy_bonus_lowers_the_loss():
    low, _ = surrogate(entropy=0.7)
    high, _ = surrogate(entropy=1.0)
    assert high < low
    np.testing.assert_allclose(low - high, ENT * 0.3, rtol=1e-3)
    grad = jax.grad(lambda e: surrogate(entropy=e)[0])(jnp.float32(0.7))
    np.testing.assert_allclose(grad, -ENT, rtol=1e-6)


def test_clipped_surrogate_gradient_vanishes_only_where_clipped():
    # d policy_loss / d log_prob_i = -(1/6) r_i A_i where the unclipped term is the min, else 0.
    log_prob = OLD_LOG_PROB + np.log(RATIO)
    grad = jax.grad(lambda lp: surrogate(log_prob=lp)[1]["policy_loss"])(jnp.asarray(log_prob))
    expected = np.where(CLIPPED, 0.0, -RATIO * ADVANTAGE / 6.0)
    np.testing.assert_allclose(np.asarray(grad), expected, rtol=1e-5, atol=1e-7)
    assert np.all(np.asarray(grad)[~CLIPPED] != 0.0)


def test_clipped_surrogate_at_ratio_one_is_minus_mean_advantage():
    loss, parts = surrogate(log_prob=OLD_LOG_PROB)
    np.testing.assert_allclose(parts["policy_loss"], -ADVANTAGE.mean(), rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(parts["approx_kl"], 0.0, atol=1e-7)
    np.testing.assert_allclose(parts["clip_fraction"], 0.0, atol=0)


def test_approx_kl_of_an_overflowing_ratio_is_inf_not_nan():
    # A stored action hundreds of the new policy's stds away overflows the ratio (exp(100) in
    # float32). The KL must read inf, so that the KL early stop skips that step, not NaN (which
    # compares False and would let the step through); (r - 1) - ln r with ln(exp(100)) gives NaN.
    log_prob = OLD_LOG_PROB.copy()
    log_prob[0] += 100.0
    _, parts = surrogate(log_prob=log_prob)
    assert np.isposinf(parts["approx_kl"])


# -- the Gaussian policy ------------------------------------------------------------------------


@pytest.mark.parametrize("log_std", [[0.0, 0.0], [-0.5, 0.7], [-2.0, 1.3]])
def test_gaussian_log_prob_matches_scipy(log_std):
    rng = np.random.default_rng(0)
    log_std = np.asarray(log_std, np.float32)
    mean = rng.normal(size=(5, 2)).astype(np.float32)
    action = (mean + rng.normal(size=(5, 2)) * 2.0).astype(np.float32)
    got = np.asarray(gaussian_log_prob(action, mean, log_std))
    want = stats.norm.logpdf(action, loc=mean, scale=np.exp(log_std)).sum(-1)
    assert got.shape == (5,)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("log_std", [[0.0, 0.0], [-0.5, 0.7], [-2.0, 1.3]])
def test_gaussian_entropy_matches_scipy(log_std):
    log_std = np.asarray(log_std, np.float32)
    got = np.asarray(gaussian_entropy(log_std))
    want = stats.norm.entropy(scale=np.exp(log_std)).sum()
    assert got.shape == ()
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize(("mean", "log_std"), [(0.0, -1.0), (0.7, 0.3), (-1.5, 1.0)])
def test_squashed_entropy_matches_the_integral(mean, log_std):
    """H(tanh u) = H(u) + E[log(1 - tanh(u)^2)], the expectation integrated by scipy's quad."""
    density = stats.norm(mean, np.exp(log_std)).pdf
    log_det = lambda u: 2 * (np.log(2) - u - np.logaddexp(0, -2 * u))  # noqa: E731
    expected = integrate.quad(lambda u: log_det(u) * density(u), -np.inf, np.inf)[0]
    want = stats.norm.entropy(scale=np.exp(log_std)) + expected
    got = squashed_entropy(jnp.full((3, 1), mean), jnp.array([log_std]))
    assert got.shape == (3,)
    np.testing.assert_allclose(got, want, atol=2e-3)


def test_squashed_entropy_is_the_gaussian_s_moved_by_the_slope_for_a_narrow_policy():
    """A std far below tanh's scale: the squash is locally linear, slope 1 - tanh(mean)^2."""
    mean, log_std = jnp.array([[0.0, 0.8]]), jnp.array([-6.0, -6.0])
    want = gaussian_entropy(log_std) + np.log(1 - np.tanh(0.8) ** 2)
    np.testing.assert_allclose(squashed_entropy(mean, log_std), [want], rtol=1e-5)


def test_squashed_entropy_is_bounded_where_the_gaussian_s_grows():
    """Past tanh's scale a wider Gaussian squashes onto the ends: the squashed entropy stays under
    log 2 (the uniform on [-1, 1]) and falls, so its bonus no longer pays for a wider std."""
    log_stds = jnp.linspace(-1.0, 3.0, 9)
    at = lambda ls: squashed_entropy(jnp.zeros((1, 1)), jnp.array([ls]))[0]  # noqa: E731
    squashed = np.asarray(jax.vmap(at)(log_stds))
    assert np.all(squashed < np.log(2.0))
    assert np.all(np.diff(np.asarray(jax.vmap(gaussian_entropy)(log_stds[:, None]))) > 0)
    assert jax.grad(at)(2.0) < 0 < jax.grad(lambda ls: gaussian_entropy(jnp.array([ls])))(2.0)
    assert squashed[-1] < squashed.max() - 0.5
