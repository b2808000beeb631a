"""The choice rule of :func:`solver.diagnose.selection.choose` on hand-made evaluations.

The hidden-effect tests exercise the rule on real trials; these cases pin down the two
comparisons it makes: a cause must stand out from the runner-up that explains the same
residuals, and a cause acting on other channels (a marker's own error) is no such rival.
"""

from __future__ import annotations

import numpy as np

from solver.diagnose.selection import ChoiceRule, Evaluation, choose, make_blocks

T = 200
DT = 0.01


def _evaluation(cause: str, parameters: dict, gain_per_frame: float, reference: float = 1.0) -> Evaluation:
    """An evaluation whose held-out gain is spread evenly over T frames (plus a little noise)."""
    rng = np.random.default_rng(len(cause))
    ref = np.full(T, reference)
    held = ref - gain_per_frame * (1 + 0.1 * rng.standard_normal(T))
    gain = float(np.sum(ref - held))
    folds = np.array_split(ref - held, 5)
    return Evaluation(
        cause=cause,
        choice=None,
        parameters=parameters,
        uncertainty=None,
        n_params=1,
        gain=gain,
        reference=float(ref.sum()),
        fold_gains=np.array([f.sum() for f in folds]),
        score=gain - np.log(T),
        held_out_costs=held,
        reference_costs=ref,
    )


DELAY = {"delay_s": 0.03}
SHIFT = {"shift_m": [0.02, 0.0, 0.0]}
MARKER = {"residual_shift_m": [0.0, 0.012, 0.0], "visible_shift_m": [0.0, 0.012, 0.0]}


def test_a_cause_on_other_channels_does_not_stand_in_the_way() -> None:
    # a plate shift and a marker offset each remove 30 % of the cost of their own channels,
    # block by block alike: both may hold (they explain different residuals), so the better
    # score is named rather than neither
    ranked = [_evaluation("plate_position_offset", SHIFT, 0.3), _evaluation("marker_offset", MARKER, 0.3)]
    ranked.sort(key=lambda e: e.score, reverse=True)
    chosen, reason = choose(ranked, ChoiceRule(), make_blocks(T, DT))
    assert chosen is not None and chosen.cause == ranked[0].cause, reason


def test_a_rival_on_the_same_channels_blocks_the_choice() -> None:
    # a delay explains the residuals as well as the plate shift, block by block: no cause stands out
    ranked = [_evaluation("plate_position_offset", SHIFT, 0.3), _evaluation("force_time_offset", DELAY, 0.3)]
    ranked.sort(key=lambda e: e.score, reverse=True)
    chosen, reason = choose(ranked, ChoiceRule(), make_blocks(T, DT))
    assert chosen is None
    assert "explains the residuals nearly as well" in reason


def test_a_negligible_estimate_is_no_contender() -> None:
    # the delay's estimate (1 ms) is below what is worth naming: the plate shift stands alone
    ranked = [_evaluation("plate_position_offset", SHIFT, 0.3), _evaluation("force_time_offset", {"delay_s": 0.001}, 0.29)]
    chosen, _ = choose(ranked, ChoiceRule(), make_blocks(T, DT))
    assert chosen is not None and chosen.cause == "plate_position_offset"
