"""Plots from results files: rows, averaging, pooled BER, the digital envelope, anchors, files."""

from __future__ import annotations

import json

import numpy as np
import pytest

import osnerf.cli
from osnerf.anchors import KODAK
from osnerf.plots import (
    make_plots,
    plot_ber,
    plot_digital_cliff,
    plot_quality_vs_snr,
)
from osnerf.results import result_rows
from osnerf.sweeps import append_record


def _eval_record(snr, seed, psnr_jscc, psnr_dig, cbr="1/16", channel="awgn", mcs=None):
    results = [
        {"scheme": "jscc", "snr_db": float(snr), "cbr": 0.0625, "psnr": psnr_jscc, "ssim": 0.8},
        {"scheme": "digital", "snr_db": float(snr), "cbr": 0.0625, "psnr": psnr_dig, "ssim": 0.7},
    ]
    point = {"snr_db": snr, **({"mcs": mcs} if mcs else {})}
    return {
        "point": point,
        "seed": seed,
        "config": {"channel": channel, "cbr": cbr, "snr_db": [snr]},
        "metrics": {"results": results},
    }


def _line(ax, label_start):
    lines = [ln for ln in ax.get_lines() if ln.get_label().startswith(label_start)]
    assert len(lines) == 1, [ln.get_label() for ln in ax.get_lines()]
    return lines[0].get_xdata(), lines[0].get_ydata()


def test_rows_flatten_results_schemes_and_plain_metrics():
    records = [
        _eval_record(1, 0, 25.0, 20.0),
        {
            "point": {"snr_db": 0},
            "seed": 3,
            "config": {"channel": "rayleigh"},
            "metrics": {
                "schemes": {"jscc": {"psnr": 21.0, "seconds": {"nerf": 1.0}}, "gt": {"psnr": 24.0}}
            },
        },
        {
            "point": {"max_seconds": 5},
            "seed": 0,
            "config": {},
            "metrics": {"psnr": 20.5, "num_views": 4},
        },
    ]
    rows = result_rows(records)
    assert len(rows) == 2 + 2 + 1
    assert rows[0] == {
        "channel": "awgn",
        "cbr": 0.0625,
        "snr_db": 1.0,
        "seed": 0,
        "scheme": "jscc",
        "scheme_kind": "jscc",  # from the scheme table
        "psnr": 25.0,
        "ssim": 0.8,
    }
    assert rows[2]["scheme"] == "jscc" and rows[2]["channel"] == "rayleigh" and rows[2]["seed"] == 3
    assert rows[3]["scheme"] == "gt" and rows[3]["scheme_kind"] == "ideal"  # the run's table
    assert rows[2]["seconds.nerf"] == 1.0 and "seconds" not in rows[2]  # nested: dotted keys
    assert rows[4] == {"max_seconds": 5, "seed": 0, "psnr": 20.5, "num_views": 4}


def test_quality_is_averaged_over_seeds_and_anchors_are_optional():
    records = [_eval_record(s, seed, 20.0 + s + seed, 10.0) for s in (1, 4) for seed in (0, 1)]
    rows = result_rows(records)
    fig = plot_quality_vs_snr(rows, "psnr", anchors=True, data_dir=None)
    ax = fig.axes[0]
    x, y = _line(ax, "jscc")
    np.testing.assert_allclose(x, [1.0, 4.0])
    np.testing.assert_allclose(y, [21.5, 24.5])  # mean over seeds 0 and 1
    labels = [ln.get_label() for ln in ax.get_lines()]
    assert sum(lb.startswith("anchor:") and "awgn" in lb for lb in labels) >= len(KODAK["awgn"])
    ax2 = plot_quality_vs_snr(rows, "psnr", anchors=False).axes[0]
    assert not any(ln.get_label().startswith("anchor") for ln in ax2.get_lines())
    # no JSCC anchors at a CBR they were not measured at
    other = result_rows([_eval_record(1, 0, 20.0, 10.0, cbr="1/6")])
    for r in other:
        r["cbr"] = 1 / 6
    ax3 = plot_quality_vs_snr(other, "psnr", anchors=True).axes[0]
    assert not any("CBR 1/16]" in ln.get_label() for ln in ax3.get_lines())


def test_ber_pools_errors_over_seeds_and_draws_theory():
    records = [
        {
            "point": {"snr_db": 4, "modulation": "qpsk"},
            "seed": seed,
            "config": {"channel": "awgn"},
            "metrics": {
                "snr_db": 4.0,
                "ber": e / 1000,
                "ber_theory": 0.0125,
                "num_bits": 1000,
                "num_errors": e,
            },
        }
        for seed, e in ((0, 10), (1, 20))
    ]
    records += [
        {
            "point": {"snr_db": 8, "modulation": "qpsk"},
            "seed": 0,
            "config": {"channel": "awgn"},
            "metrics": {
                "snr_db": 8.0,
                "ber": 0.001,
                "ber_theory": 0.0002,
                "num_bits": 3000,
                "num_errors": 3,
            },
        }
    ]
    ax = plot_ber(result_rows(records)).axes[0]
    x, y = _line(ax, "awgn, qpsk (sim.)")
    np.testing.assert_allclose(x, [4.0, 8.0])
    np.testing.assert_allclose(y, [30 / 2000, 3 / 3000])
    tx, ty = _line(ax, "awgn, qpsk (theory)")
    assert tx[0] == 4.0 and tx[-1] == 8.0 and np.all(np.diff(ty) < 0)  # falls with SNR


def test_digital_envelope_is_the_best_mcs_per_snr():
    rows = []
    for mcs, table in {
        "qpsk-1/2": {0: 10.0, 4: 26.0, 8: 26.0},
        "16qam-3/4": {0: 9.0, 4: 12.0, 8: 31.0},
    }.items():
        for snr, psnr in table.items():
            rows.append({"scheme": "digital", "mcs": mcs, "snr_db": float(snr), "psnr": psnr})
    rows.append({"scheme": "jscc", "snr_db": 0.0, "psnr": 22.0})
    ax = plot_digital_cliff(rows).axes[0]
    x, y = _line(ax, "digital envelope")
    np.testing.assert_allclose(x, [0, 4, 8])
    np.testing.assert_allclose(y, [10.0, 26.0, 31.0])
    _line(ax, "jscc (reference)")
    assert len(ax.patches) == 2  # each fixed MCS falls off its cliff (4 and 4.75 dB per dB)
    graceful = [{"scheme": "digital", "snr_db": float(s), "psnr": 20.0 + 2 * s} for s in (0, 4, 8)]
    assert len(plot_digital_cliff(graceful).axes[0].patches) == 0  # 2 dB per dB is no cliff
    with pytest.raises(ValueError, match="no rows of a digital scheme"):
        plot_digital_cliff([{"scheme": "jscc", "snr_db": 0.0, "psnr": 1.0}])


def test_fixed_mcs_curves_are_told_apart_and_the_envelope_is_not_labelled_with_one():
    """eval-codec's --mcs sets only digital_fixed; its 'digital' (envelope) rows carry no MCS."""
    records = []
    for mcs, cliff_db in (("qpsk-1/2", 2), ("16qam-3/4", 8)):
        for s in (0, 4, 8, 12):
            fixed = 30.0 if s >= cliff_db else 10.0
            records.append(
                {
                    "command": "eval-codec",
                    "point": {"mcs": mcs, "snr_db": s},
                    "seed": 0,
                    "config": {"channel": "awgn", "fixed_mcs": mcs, "snr_db": [s]},
                    "metrics": {
                        "results": [
                            {"scheme": "digital", "snr_db": s, "psnr": 20.0 + s},
                            {
                                "scheme": "digital_fixed",
                                "snr_db": s,
                                "psnr": fixed + (5 if mcs[0] == "1" else 0),
                            },
                            {"scheme": "jscc", "snr_db": s, "psnr": 25.0},
                        ]
                    },
                }
            )
    rows = result_rows(records)
    assert {r["mcs"] for r in rows if r["scheme"] == "digital_fixed"} == {"qpsk-1/2", "16qam-3/4"}
    assert {r["mcs"] for r in rows if r["scheme"] != "digital_fixed"} == {None}
    ax = plot_digital_cliff(rows).axes[0]
    labels = sorted(ln.get_label() for ln in ax.get_lines())
    assert labels == [
        "digital",
        "digital envelope (best per SNR)",
        "digital_fixed, 16qam-3/4",
        "digital_fixed, qpsk-1/2",
        "jscc (reference)",
    ]
    _, y = _line(ax, "digital envelope")
    np.testing.assert_allclose(y, [20.0, 30.0, 35.0, 35.0])  # max(digital, both fixed MCS)
    ax = plot_quality_vs_snr(rows, "psnr", anchors=False).axes[0]
    assert sorted(ln.get_label() for ln in ax.get_lines()) == [
        "digital",
        "digital_fixed, 16qam-3/4",
        "digital_fixed, qpsk-1/2",
        "jscc",
    ]
    _, y = _line(ax, "jscc")
    np.testing.assert_allclose(y, 25.0)  # the jscc rows of both MCS points pooled


def test_make_plots_writes_png_and_pdf_for_what_the_results_hold(tmp_path):
    records = [_eval_record(s, 0, 20.0 + s, 5.0 + 2 * s) for s in (1, 4, 7)]
    paths = make_plots(records, tmp_path / "figs")
    names = sorted(p.name for p in paths)
    assert names == sorted(
        f"{n}.{f}" for n in ("psnr_vs_snr", "ssim_vs_snr", "digital_cliff") for f in ("png", "pdf")
    )
    for p in paths:
        magic = b"\x89PNG\r\n\x1a\n" if p.suffix == ".png" else b"%PDF-"
        assert p.read_bytes().startswith(magic) and p.stat().st_size > 5000
    with pytest.raises(ValueError, match="nothing to plot"):
        make_plots([{"point": {}, "seed": 0, "metrics": {"loss": 1.0}}], tmp_path / "none")
    with pytest.raises(ValueError, match="--formats must be some of png, pdf, svg"):
        make_plots(records, tmp_path / "x", formats=("gif",))


def test_plot_cli(tmp_path, capsys):
    res = tmp_path / "r.jsonl"
    for s in (1, 4):
        for cbr in ("1/16", "1/8"):
            rec = _eval_record(s, 0, 20.0 + s, 10.0)
            for e in rec["metrics"]["results"]:
                e["cbr"] = cbr
            rec["point"]["cbr"] = cbr
            append_record(res, rec)
    assert (
        osnerf.cli.main(["plot", str(res), "--out", str(tmp_path / "figs"), "--formats", "png"])
        == 0
    )
    err = capsys.readouterr().err
    assert (
        "psnr_vs_cbr.png" in err and (tmp_path / "figs" / "psnr_vs_cbr.png").stat().st_size > 5000
    )
    assert (
        osnerf.cli.main(["plot", str(tmp_path / "missing.jsonl"), "--out", str(tmp_path / "m")])
        == 2
    )
    assert "does not exist" in capsys.readouterr().err
    (tmp_path / "empty.jsonl").write_text("")
    assert (
        osnerf.cli.main(["plot", str(tmp_path / "empty.jsonl"), "--out", str(tmp_path / "e")]) == 2
    )
    assert "holds no finished points" in capsys.readouterr().err
    assert not (tmp_path / "e").exists()
    json.dumps(result_rows([_eval_record(1, 0, 1.0, 2.0)]))  # rows are plain JSON


def test_bounds_are_labelled_and_rayleigh_anchors_sit_beside_fast_fading():
    rows = [
        {"scheme": s, "snr_db": v, "psnr": p, "channel": "rayleigh_fast"}
        for s, p in (("digital", 25.0), ("digital_genie", 27.0), ("ideal", 30.0))
        for v in (1.0, 4.0)
    ]
    ax = plot_quality_vs_snr(rows, "psnr", anchors=True).axes[0]
    labels = [ln.get_label() for ln in ax.get_lines()]
    assert "digital" in labels and "digital_genie (bound)" in labels and "ideal (bound)" in labels
    assert any("WITT (plot) [Kodak, rayleigh_fast" in s for s in labels)
    assert "rayleigh" not in KODAK  # block fading has no published counterpart


def test_eval_codec_files_give_the_mismatch_panel_staircase_and_outage_cdf(tmp_path):
    """eval-codec result files (planned at 4 dB, fixed MCSs, block fading) are drawn together:
    the panel marks the plan, the staircase's envelope is the best fixed MCS at each SNR, the
    CDF ends at 1 and anchors are labelled published."""
    from osnerf.plots import eval_record, plot_mismatch

    def doc(rows, **config):
        return {"config": {"cbr": 0.0625, "channel": "awgn", **config}, "seed": 0, "results": rows}

    snrs = (-2.0, 4.0, 10.0)
    panel = doc(
        [
            {"scheme": "digital", "snr_db": s, "cbr": 0.0625, "psnr": p, "plan_snr_db": 4.0}
            for s, p in zip(snrs, (14.6, 25.9, 25.9))
        ]
        + [
            {"scheme": "jscc", "snr_db": s, "cbr": 0.0625, "psnr": p, "plan_snr_db": 4.0}
            for s, p in zip(snrs, (22.5, 25.3, 27.1))
        ],
        plan_snr_db=4.0,
    )
    fixed = [
        doc(
            [
                {
                    "scheme": "digital_fixed",
                    "snr_db": s,
                    "cbr": 0.0625,
                    "psnr": p,
                    "ms_ssim": p / 40,
                    "mcs_choice": "fixed",
                }
                for s, p in zip(snrs, ys)
            ],
            fixed_mcs=m,
        )
        for m, ys in (("qpsk-1/2", (14.6, 25.1, 25.1)), ("16qam-1/2", (14.6, 14.6, 27.1)))
    ]
    fading = doc(
        [
            {
                "scheme": "digital",
                "snr_db": 4.0,
                "cbr": 0.0625,
                "psnr": 20.0,
                "psnr_per_draw": [[14.6, 25.0], [25.0, 25.0]],
            }
        ],
        channel="rayleigh",
    )
    paths = []
    for k, d in enumerate([panel, *fixed, fading]):
        paths.append(tmp_path / f"e{k}.json")
        paths[-1].write_text(json.dumps(d))
    out = tmp_path / "figs"
    assert osnerf.cli.main(["plot", *map(str, paths), "--out", str(out), "--formats", "png"]) == 0
    names = {p.stem for p in out.iterdir()}
    assert {"mismatch", "digital_cliff", "digital_cliff_ms_ssim", "outage_cdf"} <= names
    fig = plot_mismatch(result_rows([eval_record(d) for d in (panel, *fixed)]))
    ax = fig.axes[0]
    assert any(list(ln.get_xdata()) == [4.0, 4.0] for ln in ax.get_lines())  # the plan
    (dig,) = [ln for ln in ax.get_lines() if ln.get_label() == "digital"]
    assert list(dig.get_ydata()) == [14.6, 25.9, 25.9]
    cliff = plot_digital_cliff(result_rows([eval_record(d) for d in fixed]))
    x, y = _line(cliff.axes[0], "digital envelope")
    assert list(y) == [14.6, 25.1, 27.1]
    rows = result_rows([eval_record(panel)])
    labels = [ln.get_label() for ln in plot_quality_vs_snr(rows).axes[0].get_lines()]
    assert any(lb.startswith("anchor:") and lb.endswith("published]") for lb in labels)
