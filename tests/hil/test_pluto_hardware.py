"""A real ADALM-Pluto through libiio (marker ``hil``: off by default, skipped without a board).

Run with ``pytest -m hil tests/hil/test_pluto_hardware.py`` (a board on USB, or
``IIOD_REMOTE=192.168.2.1``). The loop test transmits at -30 dB TX gain in the 2.4 GHz ISM
band: cable TX to RX through a 30 dB attenuator, or use the two antennas.
"""

import numpy as np
import pytest

pytestmark = pytest.mark.hil


@pytest.fixture(scope="module")
def uri():
    try:
        from hil import find_plutos

        found = find_plutos()
    except Exception:  # noqa: BLE001 - no libiio: no hardware test
        found = []
    if not found:
        pytest.skip("no Pluto found (USB scan, IIOD_REMOTE)")
    return found[0][0]


def test_settings_read_back_quantised(uri):
    from hil import Pluto

    with Pluto.open(uri) as sdr:
        sdr.sample_rate_hz = 3_000_001
        assert abs(sdr.sample_rate_hz - 3_000_001) <= 10
        sdr.center_freq_hz = 2_450_000_123
        assert abs(sdr.rx_lo_hz - 2_450_000_123) <= 2 and abs(sdr.tx_lo_hz - sdr.rx_lo_hz) <= 2
        sdr.tx_gain_db = -10.3
        assert sdr.tx_gain_db == -10.25
        sdr.rx_gain_db = 40.7
        assert sdr.rx_gain_db == 40


def test_one_board_loops_a_tone_at_its_frequency(uri):
    from hil import Pluto

    with Pluto.open(uri) as sdr:
        sdr.sample_rate_hz = 4e6
        sdr.center_freq_hz = 2.45e9
        sdr.tx_gain_db = -30
        sdr.rx_gain_db = 30
        n, k = 4096, 205
        sdr.tx(0.5 * np.exp(2j * np.pi * k * np.arange(n) / n), cyclic=True)
        y = sdr.rx(1 << 16)[0]
        sdr.stop_tx()
    spectrum = np.abs(np.fft.fft(y)) ** 2
    peak = np.fft.fftfreq(len(y), 1 / sdr_rate(uri))[np.argmax(spectrum)]
    assert abs(peak - k * 4e6 / n) <= 2 * 4e6 / len(y)


def sdr_rate(uri) -> float:
    from hil import Pluto

    with Pluto.open(uri, configure=False) as sdr:
        return float(sdr.sample_rate_hz)
