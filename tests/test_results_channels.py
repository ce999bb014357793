"""docs/results.md's moving-drone and view-selection sections come from bench-results/."""

import json

from benchmarks import results, results_channels


def _header(results_doc: dict) -> dict:
    return {"git_commit": "0123456789abcdef", "results": results_doc}


def test_missing_files_name_the_command_that_makes_them(tmp_path):
    text = "\n".join(results_channels.sections(tmp_path))
    for name in ("doppler", "moving", "view_selection"):
        assert f"No `{name}.json` in bench-results/ (`python -m benchmarks {name}`)." in text


def test_moving_section_shows_speed_doppler_psnr_per_receiver(tmp_path):
    row = {
        "link": {
            "drone_speed_m_s": 15,
            "max_doppler_hz": 120.1,
            "median_rms_doppler_spread_hz": 3.25,
        },
        "psnr_object": {"jscc": 19.27, "digital": 18.5},
        "symbols_sent": {"jscc": 21924, "digital": 26000},
        "max_rms_doppler_spread_hz": 82.5,
        "views_with_doppler_spread": 3,
        "views_traced": 32,
        "median_measured_snr_db": 5.04,
    }
    grid = {
        "fft_size": 64,
        "subcarrier_spacing_hz": 30e3,
        "ofdm_symbol_duration_s": 80 / 1.92e6,
        "pilot_subcarrier_spacing": 1,
        "pilot_ofdm_symbols": [2, 11],
        "num_ofdm_symbols_per_slot": 14,
        "max_pilot_spacing_s": 0.000375,
    }
    ls = {
        **row,
        "csi": "ls",
        "grid": grid,
        "psnr_object": {"jscc": 18.0, "digital": 12.25},
        "views_lost": {"jscc": None, "digital": {"budget": 0, "channel": 4}},
    }
    doc = {
        "command": "osnerf run --drone-speed V",
        "snr_db_at_median_position": 5,
        "rows": [row, ls],
    }
    (tmp_path / "moving.json").write_text(json.dumps(_header(doc)))
    text = "\n".join(results_channels.moving_section(tmp_path))
    assert (
        "| 15 | perfect CSI | 120 | 3.25 | 82.5 | 3 of 32 | 5.0 | 19.27 | 18.50 | 21,924 | 26,000 "
        "| – |" in text
    )
    assert (
        "| 15 | LS pilots | 120 | 3.25 | 82.5 | 3 of 32 | 5.0 | 18.00 | 12.25 | 21,924 | 26,000 | "
        "4 |" in text
    )
    assert "pilots on every used subcarrier of OFDM symbols [2, 11] of 14" in text
    assert "at most 375 us apart" in text and "41.7 us" in text
    assert "commit 0123456" in text


def test_view_selection_section_says_joint_lost_and_links_the_picture(tmp_path):
    def run(sel, seed, views):
        return {
            "selection": sel,
            "seed": seed,
            "snr_db_at_median_position": 10.0,
            "views": views,
            "mean_expected_snr_db": 3.0 if sel == "sight" else 9.0,
        }

    stats = {n: {"mean": 18.0, "std": 0.1} for n in ("jscc", "digital", "gt")}
    doc = {
        "scene": "firefighter_shadow",
        "max_views": 2,
        "seeds": [0, 1],
        "snrs_db_at_median_position": [10.0],
        "runs": [
            run("sight", 0, [1, 4]),
            run("sight", 1, [1, 5]),
            run("joint", 0, [2, 3]),
        ],
        "by_snr_db": {
            "10": {
                "psnr_object_mean_std": {"sight": stats, "joint": stats},
                "joint_minus_sight_psnr_object_db": {"jscc": -1.2, "digital": -0.4, "gt": -1.4},
            }
        },
    }
    (tmp_path / "view_selection.json").write_text(json.dumps(_header(doc)))
    text = "\n".join(results_channels.view_selection_section(tmp_path))
    assert (
        "| 10 dB | sight | 18.00 ± 0.10 | 18.00 ± 0.10 | 18.00 ± 0.10 | [1, 4]; [1, 5] | 3.0 |"
        in text
    )
    assert "[2, 3] (every seed) | 9.0 |" in text
    assert "still lost to sight" in text and "gt -1.40" in text
    assert "No radio-map picture" in text
    (tmp_path / "view_selection").mkdir()
    (tmp_path / "view_selection" / "radiomap.png").write_bytes(b"png")
    text = "\n".join(results_channels.view_selection_section(tmp_path))
    assert "![radiomap](../bench-results/view_selection/radiomap.png)" in text


def test_results_page_holds_the_new_sections():
    doc, _ = results.render()
    for title in ("## Moving drones: uncoded BER against speed", "## Views chosen by sight"):
        assert title in doc


def test_doppler_section_states_pilots_and_ber_per_receiver(tmp_path):
    grid = {"pilot_ofdm_symbols": [2, 11], "num_ofdm_symbols_per_slot": 14}
    row = {
        "speed_m_s": 30.0,
        "max_doppler_hz": 240.2,
        "median_rms_doppler_spread_hz": 1.5,
        "snr_db": 45.0,
        "bits_per_point": 1000,
        **dict.fromkeys(results_channels.BER_COLUMNS.values(), 0.0),
        "ber_sparse_ls": 0.0018,
    }
    doc = {
        "modulation": "64qam",
        "scene": "simple_street_canyon",
        "carrier_frequency_hz": 2.4e9,
        "slots_per_transmission": 20,
        "grids": {"sparse": {**grid, "max_pilot_spacing_s": 0.00075}},
        "interpolation": "ls: linear",
        "rows": [row],
    }
    (tmp_path / "doppler.json").write_text(json.dumps(_header(doc)))
    text = "\n".join(results_channels.doppler_section(tmp_path))
    assert "| 30 | 240 | 1.50 | 45 | 0 | 1.8e-03 | 0 | 0 | 0 |" in text
    assert "pilots on OFDM symbols [2, 11] of 14 (at most 0.75 ms apart)" in text
    assert "`python -m benchmarks doppler`, commit 0123456" in text
