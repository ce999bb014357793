"""docs/results.md's sections on moving drones and radio-aware views, from ``bench-results/``.

Reads ``doppler.json`` (``python -m benchmarks doppler``), ``moving.json`` (``python -m
benchmarks moving``) and ``view_selection.json`` with its pictures under
``view_selection/`` (``python -m benchmarks view_selection``). A missing file gives a line
naming the command that makes it.
"""

from __future__ import annotations

from pathlib import Path

from benchmarks.results_common import RESULTS, commit_of, load_json, markdown_table

# BER columns of the Doppler benchmark: (pilot grid, receiver) -> the row's key
BER_COLUMNS = {
    ("sparse", "perfect CSI"): "ber_sparse_perfect",
    ("sparse", "LS"): "ber_sparse_ls",
    ("sparse", "LMMSE"): "ber_sparse_lmmse",
    ("dense", "LS"): "ber_dense_ls",
    ("dense", "LMMSE"): "ber_dense_lmmse",
}


def _doc(folder: Path, name: str) -> dict | None:
    path = folder / f"{name}.json"
    return load_json(path) if path.is_file() else None


def _missing(title: str, name: str) -> list[str]:
    return [title, "", f"No `{name}.json` in bench-results/ (`python -m benchmarks {name}`).", ""]


def _ber(x: float) -> str:
    return "0" if x == 0 else f"{x:.1e}"


def doppler_section(folder: Path = RESULTS) -> list[str]:
    title = "## Moving drones: uncoded BER against speed"
    doc = _doc(folder, "doppler")
    if doc is None:
        return _missing(title, "doppler")
    r = doc["results"]
    grids = r["grids"]
    spacing = ", ".join(
        f"{name}: pilots on OFDM symbols {g['pilot_ofdm_symbols']} of "
        f"{g['num_ofdm_symbols_per_slot']} (at most {g['max_pilot_spacing_s'] * 1e3:.2f} ms apart)"
        for name, g in grids.items()
    )
    lines = [
        title,
        "",
        f"`python -m benchmarks doppler`, commit {commit_of(doc)}: uncoded {r['modulation']} on "
        f"the OFDM link over drones' ray-traced channels in `{r['scene']}` at "
        f"{r['carrier_frequency_hz'] / 1e9:g} GHz, {r['slots_per_transmission']} slots per "
        f"transmission. Pilot grids: {spacing}. Interpolation: {r['interpolation']}.",
        "",
    ]
    header = ["speed (m/s)", "max Doppler (Hz)", "median RMS Doppler spread (Hz)", "SNR (dB)"]
    header += [f"{grid} {rx}" for grid, rx in BER_COLUMNS]
    rows = [
        [
            f"{row['speed_m_s']:g}",
            f"{row['max_doppler_hz']:.0f}",
            f"{row['median_rms_doppler_spread_hz']:.2f}",
            f"{row['snr_db']:g}",
            *(_ber(row[key]) for key in BER_COLUMNS.values()),
        ]
        for row in r["rows"]
    ]
    lines += markdown_table(header, rows)
    lines.append("")
    bits = sorted({row["bits_per_point"] for row in r["rows"]})
    lines.append(
        f"BER over the {' or '.join(f'{b:,}' for b in bits)} bits sent at each point (0: no "
        "error in them); the RMS Doppler spread is the median over the positions. "
        "A BER that stops falling as the SNR rises is an error floor: the channel moves "
        "between pilot symbols faster than the interpolation follows; denser pilots or "
        "LMMSE's time covariance lower it, perfect CSI is the bound."
    )
    return lines + [""]


RECEIVERS = {"perfect": "perfect CSI", "ls": "LS pilots", "lmmse": "LMMSE pilots"}


def _db(x: float | None) -> str:
    return "–" if x is None else f"{x:.1f}"


def _lost(row: dict, scheme: str) -> str:
    lost = (row.get("views_lost") or {}).get(scheme)
    return "–" if lost is None else str(sum(lost.values()))


def moving_section(folder: Path = RESULTS) -> list[str]:
    title = "## Moving drones end to end"
    doc = _doc(folder, "moving")
    if doc is None:
        return _missing(title, "moving")
    r = doc["results"]
    lines = [
        title,
        "",
        f"`{r['command']}` on the default scene, commit {commit_of(doc)}; SNR "
        f"{r['snr_db_at_median_position']:g} dB at the median drone position. Receivers: "
        "perfect CSI of h at each symbol's time (the run's default), or `--csi ls` / "
        "`--csi lmmse`: the same symbols on an OFDM grid with pilots, h estimated from them "
        "(jscc and digital share the link and its pilots).",
        "",
    ]
    schemes = list(r["rows"][0]["psnr_object"])
    # schemes that can lose a view (the report's views_lost is None for the others)
    lossy = [n for n in schemes if any((w.get("views_lost") or {}).get(n) for w in r["rows"])]
    rows = []
    for row in r["rows"]:
        link = row["link"]
        spread = link.get("median_rms_doppler_spread_hz")
        largest = row.get("max_rms_doppler_spread_hz")
        spread_views = (
            f"{row['views_with_doppler_spread']} of {row['views_traced']}"
            if "views_traced" in row
            else "–"
        )
        rows.append(
            [
                f"{link['drone_speed_m_s']:g}",
                RECEIVERS.get(row.get("csi", "perfect"), row.get("csi")),
                f"{link['max_doppler_hz']:.0f}",
                "–" if spread is None else f"{spread:.2f}",
                "–" if largest is None else f"{largest:.1f}",
                spread_views,
                _db(row.get("median_measured_snr_db")),
                *(f"{row['psnr_object'][n]:.2f}" for n in schemes),
                *(f"{row['symbols_sent'][n]:,}" for n in schemes),
                *(_lost(row, n) for n in lossy),
            ]
        )
    header = ["speed (m/s)", "receiver", "max Doppler (Hz)", "median RMS Doppler spread (Hz)"]
    header += ["largest spread (Hz)", "views with a spread", "median measured SNR (dB)"]
    header += [f"{n} object PSNR" for n in schemes] + [f"{n} symbols" for n in schemes]
    header += [f"{n} views lost" for n in lossy]
    lines += markdown_table(header, rows)
    carrier = r["rows"][0]["link"].get("carrier_frequency_hz")
    lines.append("")
    lines.append(
        "Max Doppler is `v f_c / c`"
        + (f" at {carrier / 1e9:g} GHz" if carrier else "")
        + ". The RMS Doppler spread is per view, over its traced paths: a view with one path "
        "has none (its channel only rotates, and perfect CSI follows the rotation); a drone's "
        "line of sight and its ground reflection leave it in nearly the same direction, so "
        "their spread is small next to the maximum Doppler. The measured SNR is the SCU's, "
        "through each link with its pilots after the receiver's estimation: a noisier "
        "estimate measures lower, and the SCU plans more symbols per view (a higher CBR, "
        "copies), so the symbols differ between receivers; within a row jscc and digital "
        "have the same budget."
    )
    grid = next((row["grid"] for row in r["rows"] if row.get("grid")), None)
    if grid:
        k = grid["pilot_subcarrier_spacing"]
        lines.append("")
        lines.append(
            f"The pilot receivers' grid: {grid['fft_size']} subcarriers at "
            f"{grid['subcarrier_spacing_hz'] / 1e3:g} kHz (the traced ones), OFDM symbols of "
            f"{grid['ofdm_symbol_duration_s'] * 1e6:.1f} us with the cyclic prefix, pilots on "
            + ("every" if k == 1 else f"every {k}th")
            + " used subcarrier "
            f"of OFDM symbols {grid['pilot_ofdm_symbols']} of {grid['num_ofdm_symbols_per_slot']}"
            f" (at most {grid['max_pilot_spacing_s'] * 1e6:.0f} us apart); LS interpolates "
            "linearly in frequency then time, LMMSE filters with a TDL-A frequency and a Jakes "
            "time covariance at the drones' speed."
        )
    return lines + [""]


def view_selection_section(folder: Path = RESULTS) -> list[str]:
    title = "## Views chosen by sight and by radio"
    doc = _doc(folder, "view_selection")
    if doc is None:
        return _missing(title, "view_selection")
    r = doc["results"]
    lines = [
        title,
        "",
        f"`osnerf run --scene {r['scene']} --channel raytraced --view-selection sight|joint "
        f"--max-views {r['max_views']}` (48 px, 500 NeRF steps, no learned renderer), seeds "
        f"{', '.join(str(s) for s in r['seeds'])}, commit {commit_of(doc)}; the SNR is set at "
        "the median drone position, so a drone behind the shed receives less. Object PSNR, "
        "mean ± std over seeds, the views each rule chose and their mean expected SNR:",
        "",
    ]
    rows = []
    for snr, summary in r["by_snr_db"].items():
        for rule, by_scheme in summary["psnr_object_mean_std"].items():
            runs = [
                run
                for run in r["runs"]
                if run["selection"] == rule and f"{run['snr_db_at_median_position']:g}" == snr
            ]
            chosen = list(dict.fromkeys(str(run["views"]) for run in runs))
            views = chosen[0] + " (every seed)" if len(chosen) == 1 else "; ".join(chosen)
            expected = sum(run["mean_expected_snr_db"] for run in runs) / len(runs)
            cells = [f"{by_scheme[n]['mean']:.2f} ± {by_scheme[n]['std']:.2f}" for n in by_scheme]
            rows.append([f"{snr} dB", rule, *cells, views, f"{expected:.1f}"])
    schemes = list(next(iter(r["by_snr_db"].values()))["psnr_object_mean_std"]["sight"])
    header = ["SNR", "rule", *schemes, "views", "views' mean expected SNR (dB)"]
    lines += markdown_table(header, rows)
    lines.append("")
    gaps = "; ".join(
        f"{snr} dB: "
        + ", ".join(f"{n} {d:+.2f}" for n, d in s["joint_minus_sight_psnr_object_db"].items())
        for snr, s in r["by_snr_db"].items()
    )
    lines.append(
        "Joint chose views with better links (last column) and still lost to sight here "
        f"(joint − sight, dB: {gaps}). gt, which sends the same "
        "views undistorted, loses too: the loss is the views' geometry, not the link. On "
        "this scene the shadowed side's geometry is worth more than its link costs."
    )
    pictures = sorted((folder / "view_selection").glob("*.png"))
    lines.append("")
    if pictures:
        lines.append(
            f"The radio map with the views of seed {r['seeds'][0]} at "
            f"{r['snrs_db_at_median_position'][0]:g} dB marked for each rule:"
        )
        lines.append("")
    lines += [f"![{p.stem}](../bench-results/view_selection/{p.name})" for p in pictures] or [
        "No radio-map picture under bench-results/view_selection/ "
        "(`python -m benchmarks view_selection`)."
    ]
    return lines + [""]


def sections(folder: Path = RESULTS) -> list[str]:
    return [*doppler_section(folder), *moving_section(folder), *view_selection_section(folder)]
