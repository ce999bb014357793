"""A real SoapySDR device (marker ``hil``: off by default, skipped without one).

Run with ``OSNERF_SOAPY_ARGS=driver=uhd,type=b200 pytest -m hil tests/hil/test_soapy_hardware.py``
(default: the first device ``SoapySDR.Device.enumerate()`` finds). The loop test transmits at
the low end of the device's TX gain range at 2.45 GHz: cable TX to RX through a 30 dB
attenuator, or use two antennas. A receive-only device (RTL-SDR) runs the settings test only.
"""

import os
import threading

import numpy as np
import pytest

pytestmark = pytest.mark.hil


@pytest.fixture(scope="module")
def args():
    from hil import DeviceNotFoundError
    from hil.soapy import find_soapy_devices

    given = os.environ.get("OSNERF_SOAPY_ARGS")
    if given:
        return given
    try:
        found = [a for a in find_soapy_devices() if "driver=remote" not in a]
    except DeviceNotFoundError:
        found = []
    if not found:
        pytest.skip("no SoapySDR device found (OSNERF_SOAPY_ARGS names one)")
    return found[0]


def test_settings_stay_within_the_devices_ranges(args):
    from hil import SoapyRadio

    with SoapyRadio.open(args) as sdr:
        r = sdr.ranges()
        lo, hi = r["center_freq_range_hz"]
        sdr.center_freq_hz = min(max(2.45e9, lo), hi)
        assert abs(sdr.center_freq_hz - min(max(2.45e9, lo), hi)) < 1e3
        lo, hi = r["rx_gain_range_db"]
        sdr.rx_gain_db = (lo + hi) / 2
        assert lo <= sdr.rx_gain_db <= hi
        with pytest.raises(ValueError, match="center_freq_hz must be in"):
            sdr.center_freq_hz = r["center_freq_range_hz"][1] * 2


def test_one_device_loops_a_tone_at_its_frequency(args):
    from hil import SoapyRadio

    with SoapyRadio.open(args) as sdr:
        if not sdr.can_transmit:
            pytest.skip(f"{args} is receive-only")
        sdr.sample_rate_hz = 4e6
        sdr.center_freq_hz = 2.45e9
        sdr.tx_gain_db = sdr.ranges()["tx_gain_range_db"][0]
        n, k = 1 << 18, 51_200  # a 781.25 kHz tone
        tone = (0.5 * np.exp(2j * np.pi * k * np.arange(n) / n)).astype(np.complex64)
        out = {}
        rx = threading.Thread(target=lambda: out.setdefault("y", sdr.rx(3 * n)))
        rx.start()
        sdr.tx(tone)
        rx.join(30)
        fs = sdr.sample_rate_hz
    y = out["y"][0]
    assert sdr.last_counts["rx"].overflows == 0
    spectrum = np.abs(np.fft.fft(y)) ** 2
    peak = np.fft.fftfreq(len(y), 1 / fs)[np.argmax(spectrum)]
    assert abs(peak - k * 4e6 / n) <= 2 * fs / len(y) + 5e3  # within the crystals' offset
