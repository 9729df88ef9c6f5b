"""The plots of a discrepancy report: drawn from a run's arrays (which ``results.json`` does not
hold), beside the ``report.md`` that :mod:`ctrplan.discrepancy.outputs.report` formats."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["write_plots"]


def _tangential(residual, tip):
    """Residual component along e_z x tip direction (rotation about the base axis) [m]."""
    t = np.column_stack([-tip[:, 1], tip[:, 0], np.zeros(len(tip))])
    t /= np.linalg.norm(t, axis=1, keepdims=True) + 1e-300
    return np.einsum("ij,ij->i", residual, t)


def _errors_arrays(e) -> dict:
    return {"position": e.position, "angle": e.angle, "residual": e.residual_base, "tip_base": e.tip_base}


def _arrays(result) -> dict:
    """The arrays the plots draw [SI]."""
    split, data, final = result.split, result.setup.data, result.final
    return {"dev_eta": data.take(split.dev_rows).eta, "test_eta": data.take(split.test_rows).eta,
            "oof": _errors_arrays(result.baseline.oof),
            "oof_final": None if final is None else _errors_arrays(final.oof),
            "test_before": _errors_arrays(result.test.baseline), "test_after": _errors_arrays(result.test.final),
            "test_file": _errors_arrays(result.test.file)}


def write_plots(result, out: Path) -> list[str]:
    """Draw the report's plots of ``result`` into ``out``: the test split's error histograms before
    and after (``error_histograms.png``) and the out-of-fold residual about the base axis by the
    direction of the last relative rotation (``residuals_by_direction.png``).

    Parameters
    ----------
    result : DiscrepancyResult
        From :func:`ctrplan.discrepancy.workflow.run_discrepancy` (its arrays, SI units; the plots
        print mm and degrees).
    out : Path
        The report folder.

    Returns
    -------
    list of str
        The file names written, in ``out``.

    Raises
    ------
    OSError
        A plot cannot be written.
    """
    from ...plots import new_figure, save_figure


    a = _arrays(result)
    files = []
    fig = new_figure((10, 3.8))
    axes = fig.subplots(1, 2)
    before, after = a["test_before"]["position"] * 1e3, a["test_after"]["position"] * 1e3
    top = np.nanmax(np.concatenate([before, after]))
    bins = np.linspace(0, top if np.isfinite(top) and top > 0 else 1.0, 40)
    final = result.test.label
    axes[0].hist(before[np.isfinite(before)], bins, alpha=0.6, label="baseline (standard, calibrated)")
    axes[0].hist(after[np.isfinite(after)], bins, alpha=0.6, label=final)
    axes[0].set_xlabel("test-split tip position error [mm]")
    axes[0].set_ylabel("samples")
    axes[0].legend(fontsize=8)
    ab, aa = np.rad2deg(a["test_before"]["angle"]), np.rad2deg(a["test_after"]["angle"])
    if np.isfinite(ab).any():
        top = np.nanmax(np.concatenate([ab, aa]))
        bins = np.linspace(0, top if top > 0 else 1.0, 40)
        axes[1].hist(ab[np.isfinite(ab)], bins, alpha=0.6, label="baseline")
        axes[1].hist(aa[np.isfinite(aa)], bins, alpha=0.6, label="final")
        axes[1].legend(fontsize=8)
    axes[1].set_xlabel("test-split tip tangent error [deg]")
    fig.suptitle("Error histograms on the untouched test split, before and after")
    files.append(save_figure(fig, out / "error_histograms.png").name)

    eta = np.asarray(a["dev_eta"], int)
    combos = sorted({tuple(e) for e in eta}, reverse=True)
    fig = new_figure((10, 3.8))
    axes = fig.subplots(1, 2, sharey=True)
    panels = [(axes[0], a["oof"], "baseline"), (axes[1], a["oof_final"] or a["oof"], "final model")]
    for ax, arr, title in panels:
        tang = _tangential(np.asarray(arr["residual"]), np.asarray(arr["tip_base"])) * 1e3
        data = [tang[np.all(eta == np.array(c), axis=1) & np.isfinite(tang)] for c in combos]
        ax.boxplot(data, showfliers=False)
        ax.set_xticks(range(1, len(combos) + 1))
        ax.set_xticklabels([",".join("+" if v > 0 else "-" if v < 0 else "0" for v in c) for c in combos])
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_xlabel("direction of the last relative rotation eta (pair 1, pair 2, ...)")
        ax.set_title(title)
    axes[0].set_ylabel("out-of-fold residual about the base axis [mm]")
    fig.suptitle("Out-of-fold residual (tangential component) by direction of the last relative rotation")
    files.append(save_figure(fig, out / "residuals_by_direction.png").name)
    return files
