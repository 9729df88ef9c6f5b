"""The split's blocks and buffer against serially correlated residuals (ctrplan.discrepancy.measured.split),
by simulation independent of the mechanics: AR(1) residuals along a continuous motion of 500
samples, the autocorrelation at the buffer measured here with numpy, and the distances between
the rows a fold is fitted on and the rows it is judged on counted here.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from ctrplan.discrepancy.measured.data import MeasuredData
from ctrplan.choices import BlocksKept, BufferReason
from ctrplan.discrepancy.options import DiscrepancyOptions
from ctrplan.discrepancy.outputs.words import buffer_text, split_text
from ctrplan.discrepancy.measured.split import (BUFFER_AUTOCORRELATION, MIN_TEST_UNITS, MIN_UNITS_PER_FOLD, choose_blocks,
                                       choose_buffer, lengthen_blocks, make_split)
from ctrplan.history import MotionRecord

K = 500


def _data(k: int = K, sequence=None, config_id=None) -> MeasuredData:
    """Toy data of ``k`` samples (only the bookkeeping the split reads is meaningful)."""
    z = np.zeros((k, 2))
    sequence = np.zeros(k, int) if sequence is None else np.asarray(sequence)
    config_id = np.arange(k) if config_id is None else np.asarray(config_id)
    return MeasuredData(alpha=z, beta=z, tip=np.zeros((k, 3)), tangent=None, eta=np.zeros((k, 1), int),
                        translation_last=np.zeros((k, 1), bool), sequence=sequence, config_id=config_id,
                        subset=None, time=None, file="toy.csv", frame="robot",
                        record=MotionRecord(z, z, sequence=sequence), rows=np.arange(k),
                        given_eta=np.zeros((k, 1), int))


def _ar1(phi: float, sequence, seed: int) -> np.ndarray:
    """Unit-variance AR(1) residual vectors, shape (K, 3), restarted at every new sequence."""
    rng = np.random.default_rng(seed)
    w = rng.normal(size=(len(sequence), 3))
    r = np.empty_like(w)
    for i in range(len(sequence)):
        new = i == 0 or sequence[i] != sequence[i - 1]
        r[i] = w[i] if new else phi * r[i - 1] + np.sqrt(1 - phi ** 2) * w[i]
    return r


def _acf(r: np.ndarray, sequence, rows, lag: int) -> float:
    """Autocorrelation at ``lag`` record positions of the rows present, pooled over components and
    sequences (each sequence's mean removed), computed here without the module."""
    num = cnt = var = n = 0.0
    for s in np.unique(sequence):
        on = sequence == s
        x = r[on] - r[on].mean(axis=0)
        pos = rows[on] - rows[on].min()
        grid = np.full((pos.max() + 1, 3), np.nan)
        grid[pos] = x
        prod = np.sum(grid[lag:] * grid[:-lag], axis=1)
        num += np.nansum(prod)
        cnt += np.sum(np.isfinite(prod))
        var += np.sum(x * x)
        n += x.shape[0]
    return float((num / cnt) / (var / n))


def _dev_acf(split, r: np.ndarray, lag: int) -> float:
    dev = split.dev_rows
    return _acf(r[dev], split.data.sequence[dev], split.data.rows[dev], lag)


def _assert_buffers_hold(split) -> None:
    """No row a fit uses lies within ``buffer`` record positions of a row it is judged on (the
    test split, and fold k's validation rows for fold k), within one sequence."""
    seq, pos = split.data.sequence, split.data.rows
    for k in [None, *range(split.n_folds)]:
        cal = split.calibration_rows(k)
        judged = split.test_rows | (split.fold == k if k is not None else False)
        for s in np.unique(seq):
            on = seq == s
            a, b = pos[on & cal], pos[on & judged]
            if a.size and b.size:
                assert np.min(np.abs(a[:, None] - b[None, :])) > split.buffer, (k, s)
        assert not np.any(cal & judged)


def _assert_units_whole(split) -> None:
    """Every unit in exactly one fold (or the test split), each fold with MIN_UNITS_PER_FOLD units."""
    for u in np.unique(split.units):
        assert np.unique(split.fold[split.units == u]).size == 1
    assert np.all(split.fold[split.test_rows] == -1) and np.all(split.fold[split.dev_rows] >= 0)
    for k in range(split.n_folds):
        assert np.unique(split.units[split.fold == k]).size >= MIN_UNITS_PER_FOLD


def test_strong_serial_correlation_lengthens_the_blocks_until_the_buffer_reaches_the_threshold():
    """AR(1) residuals, phi 0.75, on 500 samples: the capped buffer of the 10-sample blocks
    (5 samples) leaves an autocorrelation of about 0.18 next to every validated block; with the
    development blocks lengthened (as far as the split's 10 folds of 2 units allow), the
    residuals' autocorrelation at lag ``buffer + 1`` (the nearest a fit keeps), measured here, is
    at or under 0.1 and the buffer at most half a block. Catches a buffer that is capped while
    the autocorrelation is still large (the blocks not lengthened), and a recorded
    autocorrelation that is not the one at the buffer."""
    split = make_split(_data(), seed=0)
    r = _ar1(0.75, split.data.sequence, seed=1)
    dev = split.dev_rows
    capped = choose_buffer(r[dev], split.data.take(dev), split.block_samples)
    assert capped.reason == BufferReason.HALF_A_BLOCK and _dev_acf(split, r, capped.samples + 1) > 0.13  # the old leak
    capped = capped.samples
    out = lengthen_blocks(split, r[dev])
    assert out.block_samples > split.block_samples and out.buffer <= out.block_samples // 2
    assert out.buffer > capped
    measured = _dev_acf(out, r, out.buffer + 1)
    assert measured <= BUFFER_AUTOCORRELATION + 0.02
    assert out.buffer_autocorrelation == pytest.approx(measured, abs=1e-9)
    assert out.buffer_autocorrelation <= BUFFER_AUTOCORRELATION
    assert out.rule.recut_block == out.block_samples and out.buffer_choice.lengthened_to == out.block_samples
    assert out.buffer_choice.lengthened_from == split.block_samples
    assert f"at least {out.block_samples} samples" in split_text(out.as_dict())
    assert "lengthened" in buffer_text(out.as_dict())
    d = out.as_dict()
    assert d["block_samples"] == out.block_samples and d["buffer_samples"] == out.buffer
    assert d["buffer_autocorrelation"] == pytest.approx(out.buffer_autocorrelation)


@pytest.mark.parametrize("phi", [0.85, 0.95])
def test_lengthening_never_costs_a_fold(phi):
    """AR(1) residuals whose autocorrelation asks for blocks longer than 10 folds of 2 units allow
    (phi 0.85 and 0.95 on 500 samples, as a pilot residual that holds a slowly varying missing
    effect): the blocks are lengthened only while the split keeps its 10 folds with at least 2
    development units each, and the note gives the autocorrelation left at the buffer. Catches
    the lengthening that traded folds for buffer (5 folds of long blocks), which cost the
    comparisons that name an effect most of their power (the simulation of
    ``lengthen_blocks``' notes, checked in tests/test_discrepancy_statistics.py)."""
    split = make_split(_data(), seed=0)
    assert split.n_folds == 10
    r = _ar1(phi, split.data.sequence, seed=3)
    out = lengthen_blocks(split, r[split.dev_rows])
    assert out.n_folds == 10 and out.n_dev_units >= 10 * MIN_UNITS_PER_FOLD
    assert out.block_samples > split.block_samples and out.buffer > split.block_samples // 2
    _assert_units_whole(out)
    _assert_buffers_hold(out)
    left = _dev_acf(out, r, out.buffer + 1)
    assert left > BUFFER_AUTOCORRELATION and out.buffer_choice.reason == BufferReason.HALF_A_BLOCK
    assert out.buffer_choice.min_units == 10 * MIN_UNITS_PER_FOLD
    assert f"still {left:.2f} at lag {out.buffer + 1}" in buffer_text(out.as_dict())


def test_weak_serial_correlation_keeps_the_original_blocks_and_folds():
    """AR(1) residuals, phi 0.3: the buffer (2 samples) fits within half a 10-sample block, so
    the units, the folds and the block length stay those of :func:`make_split`, and the buffer is
    the one of :func:`choose_buffer`. Catches blocks lengthened when the autocorrelation does not
    need it (fewer folds and units for nothing)."""
    split = make_split(_data(), seed=0)
    r = _ar1(0.3, split.data.sequence, seed=2)
    dev = split.dev_rows
    out = lengthen_blocks(split, r[dev])
    np.testing.assert_array_equal(out.units, split.units)
    np.testing.assert_array_equal(out.fold, split.fold)
    assert out.block_samples == split.block_samples == 10 and out.n_folds == split.n_folds
    assert out.buffer_choice == choose_buffer(r[dev], split.data.take(dev), split.block_samples)
    assert out.buffer == out.buffer_choice.samples and out.buffer_choice.lengthened_to is None
    assert _dev_acf(out, r, out.buffer + 1) <= BUFFER_AUTOCORRELATION + 0.03


@pytest.mark.parametrize("phi", [0.85, 0.95])
def test_lengthened_folds_keep_their_training_rows_a_buffer_away_and_the_test_split_untouched(phi):
    """Two motions of 250 samples, AR(1) residuals: after lengthening, no row of fold k's fit
    (nor of the fit on all development samples) lies within ``buffer`` samples of a row of fold k
    or of the test split in the same motion; every unit lies in one fold; the test split keeps its
    rows and its blocks, and a development block never spans a test block. Catches folds dealt
    before the re-cut (a unit cut between folds), buffers sized for the old blocks, and a test
    split redrawn from the residuals."""
    seq = np.repeat([0, 1], K // 2)
    split = make_split(_data(sequence=seq), seed=4)
    r = _ar1(phi, seq, seed=5)
    out = lengthen_blocks(split, r[split.dev_rows])
    assert out.block_samples > split.block_samples and out.buffer > split.block_samples // 2
    _assert_buffers_hold(out)
    _assert_units_whole(out)
    np.testing.assert_array_equal(out.test_rows, split.test_rows)
    for u in np.unique(split.units[split.test_rows]):           # the test blocks, as they were
        rows = split.units == u
        assert np.unique(out.units[rows]).size == 1 and np.array_equal(out.units == out.units[rows][0], rows)
    for u in np.unique(out.units[out.dev_rows]):                 # a development block: one stretch
        idx = np.flatnonzero(out.units == u)
        assert np.unique(seq[idx]).size == 1 and not out.test_rows[idx.min():idx.max() + 1].any()


def test_when_the_minimums_stop_the_lengthening_the_note_says_the_autocorrelation_left():
    """AR(1) residuals, phi 0.95, on 500 samples: no split keeps the minimums with a buffer at
    the threshold. The blocks grow only as far as the stretches between test blocks, the folds'
    units (the split's folds, at least 2 units each), the test split's 8 units and every fit's 20 calibration samples
    allow; the note says the buffer is half a block and gives the autocorrelation still left
    there, which is the one measured here. Catches lengthening past a minimum (a fold without
    units, a fit without samples) and a note that claims the threshold was reached."""
    split = make_split(_data(), seed=0)
    r = _ar1(0.95, split.data.sequence, seed=6)
    out = lengthen_blocks(split, r[split.dev_rows], min_fit_samples=20)
    assert out.n_test_units >= MIN_TEST_UNITS and out.n_folds >= 2
    _assert_units_whole(out)
    _assert_buffers_hold(out)
    fits = [int(out.calibration_rows(k).sum()) for k in [None, *range(out.n_folds)]]
    assert min(fits) >= 20
    left = _dev_acf(out, r, out.buffer + 1)
    assert left > BUFFER_AUTOCORRELATION and out.buffer_autocorrelation == pytest.approx(left, abs=1e-9)
    assert out.buffer_choice.reason == BufferReason.HALF_A_BLOCK
    assert out.buffer_choice.still == pytest.approx(left, abs=1e-9)
    note = buffer_text(out.as_dict())
    assert "half a block" in note and f"still {left:.2f} at lag {out.buffer + 1}" in note
    # a fit minimum out of reach: the blocks the test split was chosen with, as before
    kept = lengthen_blocks(split, r[split.dev_rows], min_fit_samples=10_000)
    np.testing.assert_array_equal(kept.units, split.units)
    assert kept.buffer == split.block_samples // 2 and kept.buffer_choice.kept == BlocksKept.MINIMUMS
    assert kept.buffer_choice.min_fit_samples == 10_000 and "still" in buffer_text(kept.as_dict())


def test_folds_asked_for_keep_their_units_per_fold_and_asked_blocks_stay():
    """phi 0.85 with 10 folds asked: 20 development units must remain, so the blocks grow less
    than for the default folds and the note says the autocorrelation left; with 50 blocks asked
    nothing is re-cut and the note says so. Catches lengthening that drops below 2 units per
    asked fold, and lengthening that overrides blocks the user fixed."""
    r = _ar1(0.85, np.zeros(K, int), seed=7)
    split = make_split(_data(), n_folds=10, seed=0)
    out = lengthen_blocks(split, r[split.dev_rows], n_folds=10)
    assert out.n_folds == 10 and out.n_dev_units >= 10 * MIN_UNITS_PER_FOLD
    _assert_units_whole(out)
    _assert_buffers_hold(out)
    if out.buffer_autocorrelation > BUFFER_AUTOCORRELATION:
        assert out.buffer_choice.reason == BufferReason.HALF_A_BLOCK and "still" in buffer_text(out.as_dict())
    asked = make_split(_data(), n_blocks=50, seed=0)
    same = lengthen_blocks(asked, r[asked.dev_rows], n_blocks=50)
    np.testing.assert_array_equal(same.fold, asked.fold)
    assert same.buffer == 5 and same.buffer_choice.kept == BlocksKept.ASKED
    assert "as asked" in buffer_text(same.as_dict())


def test_arguments_that_change_the_test_split_or_residuals_of_other_rows_are_refused():
    """The split is remade from its arguments: other arguments (another test fraction) would give
    another test split, and residuals not of the development rows another autocorrelation.
    Catches a lengthening that silently redraws the test split."""
    split = make_split(_data(), test_fraction=0.2, seed=0)
    r = _ar1(0.85, np.zeros(K, int), seed=8)
    with pytest.raises(ValueError, match="test split"):
        lengthen_blocks(split, r[split.dev_rows], test_fraction=0.3)
    with pytest.raises(ValueError, match="shape"):
        lengthen_blocks(split, r)


def test_configuration_groups_have_no_buffer_whatever_the_residuals():
    """Configuration groups have no serial order between them: buffer 0, units and folds kept.
    Catches a buffer or re-cut applied to groups."""
    config = np.repeat(np.arange(60), 4)
    split = make_split(_data(240, sequence=np.arange(240), config_id=config), seed=5)
    out = lengthen_blocks(split, _ar1(0.95, np.zeros(240, int), seed=9)[split.dev_rows])
    assert out.buffer == 0 and out.unit_kind == "configuration group"
    np.testing.assert_array_equal(out.fold, split.fold)


def test_the_workflow_step_passes_the_options_and_keeps_every_fit_above_its_parameters():
    """:func:`choose_blocks` lengthens with the options the split was made with, and every fit
    keeps more samples than the baseline's parameters plus the largest effect's (30 here: the
    buffer stops short of the one that leaves 16 samples in a fold fit). Catches options not
    passed on and fits left with fewer samples than parameters."""
    options = DiscrepancyOptions(n_folds=3)
    split = make_split(_data(), n_folds=3, seed=0)
    r = _ar1(0.9, np.zeros(K, int), seed=10)
    base_names = tuple(f"p{i}" for i in range(30))
    setup = SimpleNamespace(data=split.data, robot=None, effects=(), base_names=base_names)
    out = choose_blocks(setup, split, r[split.dev_rows], options)
    direct = lengthen_blocks(split, r[split.dev_rows], n_folds=3, min_fit_samples=31)
    np.testing.assert_array_equal(out.fold, direct.fold)
    assert out.n_folds == 3 and out.buffer == direct.buffer > split.block_samples // 2
    assert out.buffer < lengthen_blocks(split, r[split.dev_rows], n_folds=3).buffer
    assert min(int(out.calibration_rows(k).sum()) for k in [None, *range(out.n_folds)]) > len(base_names)


def test_every_fit_keeps_more_samples_than_a_pair_of_effects_has_parameters():
    """The minimum a lengthening keeps in every fit covers the largest pair of stage 8 (the baseline,
    off-plane precurvature and the registration on the tube pair: 3 + 2 + 6). Catches a minimum
    sized for one effect, which left a pair fit 12 samples for 14 parameters and ended a run in a
    traceback."""
    from pathlib import Path

    from ctrplan.design import motion_data
    from ctrplan.discrepancy.measured.split import _fit_minimum
    from ctrplan.io.robot_file import load_robot

    robot = load_robot(Path(__file__).resolve().parents[1] / "model" / "ha2019-table1-tube-pair.toml")
    t = np.arange(50) * 0.1
    data = motion_data(robot, t, np.linspace(0.0, 1.0, 50)[:, None])
    base = ("precurvature_y_1", "precurvature_y_2", "k_xy_relative_2")
    setup = SimpleNamespace(robot=robot, data=data, effects=("offplane", "registration", "time_offset"),
                            base_names=base)
    assert _fit_minimum(setup) == 3 + 6 + 2


def test_the_split_and_buffer_records_are_said_with_their_own_numbers():
    """Records written by hand with distinct numbers: the sentences name each number where it
    belongs and the reason's words, also after a round trip through JSON. Catches a sentence that
    reads the wrong field (units for samples, the first block length for the re-cut one), and a
    kind that loses its words when stored."""
    import json

    from ctrplan.choices import SplitUnit
    from ctrplan.discrepancy.measured.split import BufferChoice, SplitRule

    rule = SplitRule(n_units=37, unit_kind=SplitUnit.TIME_BLOCK, block_samples=13, blocks_asked=False,
                     n_test_units=8, n_test_samples=104, test_fraction=0.2, test_at_minimum=True,
                     n_development_units=11, n_development_samples=377, recut_block=41, n_folds=5,
                     folds_asked=True, subset_ignored=True)
    choice = BufferChoice(20, BufferReason.HALF_A_BLOCK, lag_one=0.97, still=0.456, lengthened_from=13,
                          lengthened_to=41, min_units=4, min_fit_samples=1)
    split = json.loads(json.dumps({"rule": rule.as_dict(), "buffer": choice.as_dict()}))
    assert split_text(split) == (
        "37 time blocks of 13 samples (50 at most, of at least 10 samples); test split: 8 units "
        "(104 samples; at least 8 units, more than 20%) held back before any fit; development: 11 units (377 samples; "
        "the stretches between test blocks re-cut into blocks of at least 41 samples, a shorter stretch whole) in 5 "
        "cross-validation folds (GroupKFold; as asked) (the file's 'subset' column is not used for the split)")
    assert buffer_text(split) == (
        "20 samples (half a block, the most allowed): the residuals' autocorrelation is still 0.46 at lag 21 "
        "(lag 1: 0.97); development blocks lengthened from 13 to at least 41 samples, the longest within the "
        "stretches between test blocks that leave 4 development units and 1 calibration sample in every fit")
    groups = {"rule": {**rule.as_dict(), "unit_kind": str(SplitUnit.CONFIGURATION_GROUP), "block_samples": None,
                       "recut_block": None, "subset_ignored": False, "folds_asked": False, "test_at_minimum": False},
              "buffer": BufferChoice(0, BufferReason.CONFIGURATION_GROUPS).as_dict()}
    assert split_text(groups).startswith("37 configuration groups; test split: 8 units (104 samples; 20% of the units)")
    assert split_text(groups).endswith("(GroupKFold; 10 at most, with at least 2 development units each)")
    assert buffer_text(groups).startswith("no buffer: the units are configuration groups")
