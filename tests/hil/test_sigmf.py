"""SigMF write / read / replay with the sigmf package; corrupt and truncated files fail clearly."""

import json

import numpy as np
import pytest

from hil import Annotation, SigmfError, SigmfReplay, read_sigmf, write_sigmf
from hil.iq import to_int8_iq


def samples(n=1000, seed=0):
    rng = np.random.default_rng(seed)
    return (rng.uniform(-0.9, 0.9, n) + 1j * rng.uniform(-0.9, 0.9, n)).astype(np.complex64)


def test_ci8_round_trip_with_annotations(tmp_path):
    x = samples()
    raw = to_int8_iq(x)
    anns = [
        Annotation(10, 200, "frame 0", snr_db=14.2, crc_ok=True, extra={"frame": 0}),
        Annotation(300, 200, "frame 1", snr_db=-1.5, crc_ok=False),
    ]
    meta = write_sigmf(
        tmp_path / "cap",
        raw,
        sample_rate_hz=4e6,
        center_freq_hz=2.45e9,
        annotations=anns,
        hw="HackRF One (emulated)",
    )
    assert meta.name == "cap.sigmf-meta" and (tmp_path / "cap.sigmf-data").stat().st_size == 2000
    doc = json.loads(meta.read_text())
    assert doc["global"]["core:datatype"] == "ci8" and doc["global"]["core:sample_rate"] == 4e6
    assert doc["captures"][0]["core:frequency"] == 2.45e9
    rec = read_sigmf(tmp_path / "cap")
    assert np.array_equal(rec.samples, raw.astype(np.float32).view(np.complex64) / 128)
    assert rec.sample_rate_hz == 4e6 and rec.center_freq_hz == 2.45e9
    assert [
        (a.sample_start, a.sample_count, a.label, a.snr_db, a.crc_ok) for a in rec.annotations
    ] == [(10, 200, "frame 0", 14.2, True), (300, 200, "frame 1", -1.5, False)]
    assert rec.annotations[0].extra == {"frame": 0}


def test_cf32_round_trip_is_exact(tmp_path):
    x = samples(seed=1)
    write_sigmf(tmp_path / "proc", x[None, :], sample_rate_hz=2e6, datatype="cf32_le")
    rec = read_sigmf(tmp_path / "proc.sigmf-meta")
    assert rec.datatype == "cf32_le" and np.array_equal(rec.samples, x)


def test_corrupt_data_fails_the_hash(tmp_path):
    write_sigmf(tmp_path / "c", to_int8_iq(samples()), sample_rate_hz=2e6)
    data = tmp_path / "c.sigmf-data"
    b = bytearray(data.read_bytes())
    b[100] ^= 0xFF
    data.write_bytes(bytes(b))
    with pytest.raises(SigmfError, match="corrupt or truncated"):
        read_sigmf(tmp_path / "c")


def test_truncated_data_fails(tmp_path):
    write_sigmf(tmp_path / "t", to_int8_iq(samples()), sample_rate_hz=2e6)
    data = tmp_path / "t.sigmf-data"
    data.write_bytes(data.read_bytes()[:-501])
    with pytest.raises(SigmfError, match="t.sigmf"):
        read_sigmf(tmp_path / "t")


def test_broken_or_missing_metadata_fails(tmp_path):
    write_sigmf(tmp_path / "m", to_int8_iq(samples()), sample_rate_hz=2e6)
    meta = tmp_path / "m.sigmf-meta"
    meta.write_text(meta.read_text()[:50])
    with pytest.raises(SigmfError, match="not valid JSON"):
        read_sigmf(tmp_path / "m")
    with pytest.raises(SigmfError, match="metadata not found"):
        read_sigmf(tmp_path / "nothing")


def test_replay_through_the_receive_interface(tmp_path):
    x = samples(500, seed=2)
    write_sigmf(tmp_path / "r", x, sample_rate_hz=2e6, center_freq_hz=915e6, datatype="cf32_le")
    with SigmfReplay(tmp_path / "r") as src:
        assert src.sample_rate_hz == 2e6 and src.center_freq_hz == 915e6
        a, b = src.rx(300), src.rx(300)
    assert a.shape == (1, 300) and np.array_equal(a[0], x[:300])
    assert np.array_equal(b[0, :200], x[300:]) and np.all(b[0, 200:] == 0)


def test_data_file_one_byte_short_blames_the_data_file(tmp_path):
    write_sigmf(tmp_path / "s", to_int8_iq(samples()), sample_rate_hz=2e6)
    data = tmp_path / "s.sigmf-data"
    data.write_bytes(data.read_bytes()[:-1])
    with pytest.raises(SigmfError, match=r"s\.sigmf-data: .*the data file is damaged"):
        read_sigmf(tmp_path / "s")


def test_empty_recording_is_refused_and_writes_nothing(tmp_path):
    with pytest.raises(ValueError, match="at least one sample"):
        write_sigmf(tmp_path / "e", np.zeros(0, np.int8), sample_rate_hz=2e6)
    assert list(tmp_path.iterdir()) == []
