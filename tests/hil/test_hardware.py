"""Real HackRF One boards over libusb (marker ``hil``: off by default, skipped without a board).

Run with ``pytest -m hil tests/hil``. The two-board test transmits at low power in the
2.4 GHz ISM band: connect the boards by cable with an attenuator, or keep them apart.
"""

import numpy as np
import pytest

pytestmark = pytest.mark.hil


def _serials():
    try:
        import usb.core

        from hil.hackrf import protocol

        devs = usb.core.find(find_all=True, idVendor=protocol.VENDOR_ID)
        return [d.serial_number for d in devs if d.idProduct in protocol.PRODUCT_IDS]
    except Exception:  # noqa: BLE001 - no libusb, no permission: no hardware test
        return []


@pytest.fixture(scope="module")
def serials():
    s = _serials()
    if not s:
        pytest.skip("no HackRF attached (or no libusb-1.0)")
    return s


def test_identity_and_settings_read_back(serials):
    from hil import HackRF

    with HackRF.open(serials[0]) as sdr:
        assert sdr.board_id in (2, 4, 5) and len(sdr.serial_number) == 32
        sdr.sample_rate_hz = 4e6
        sdr.center_freq_hz = 2.45e9
        sdr.lna_gain_db, sdr.vga_gain_db = 17, 21
        assert (sdr.sample_rate_hz, sdr.baseband_filter_hz, sdr.lna_gain_db, sdr.vga_gain_db) == (
            4e6,
            2_500_000,
            16,
            20,
        )


def test_receive_at_4_msps_without_overruns(serials):
    from hil import HackRF

    with HackRF.open(serials[0]) as sdr:
        sdr.sample_rate_hz = 4e6
        x = sdr.rx(4_000_000)
        assert x.shape == (1, 4_000_000) and x.dtype == np.complex64
        assert np.max(np.abs(x.real)) <= 1.0
        assert sdr.last_stats.host_dropped_bytes == 0 and sdr.last_stats.device_shortfalls <= 0


def test_two_boards_see_each_other(serials):
    if len(serials) < 2:
        pytest.skip("needs two HackRFs")
    import threading

    from hil import HackRF

    with HackRF.open(serials[0]) as tx, HackRF.open(serials[1]) as rx:
        for d in (tx, rx):
            d.sample_rate_hz = 4e6
            d.center_freq_hz = 2.45e9
        tx.txvga_gain_db = 10
        tone = 0.5 * np.exp(2j * np.pi * 0.05 * np.arange(400_000))
        out = {}
        t = threading.Thread(target=lambda: out.setdefault("y", rx.rx(1_000_000)))
        t.start()
        tx.tx(tone)
        t.join()
        spec = np.abs(np.fft.fft(out["y"][0])) ** 2
        k = int(np.argmax(spec))
        f = (k if k < len(spec) // 2 else k - len(spec)) * 4e6 / len(spec)
        assert abs(f - 0.05 * 4e6) < 150e3  # the tone, within two crystals' offsets
