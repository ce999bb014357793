"""Radios state what they did: every emulated path (two HackRFs, one Pluto) takes its air from
the same `osnerf ota` flags, a real air refuses them, each radio checks its own ranges, URIs
are parsed, results carry the measured SNR beside the requested one; `--overwrite` replaces
the whole output set; flags for schemes that are not sent are refused."""

import gc
import json

import numpy as np
import pytest

import phy
from osnerf.cli import main

adi = pytest.importorskip("adi", reason="pyadi-iio (and libiio0) are not installed")
pytestmark = pytest.mark.skipif(
    not all(
        hasattr(phy, n) for n in ("FrameConfig", "build_frame", "find_frames", "receive_frame")
    ),
    reason="phy's frame API is not in this checkout",
)

from hil import EmulatedPluto, HilError, IiodServer, Pluto  # noqa: E402
from osnerf.ota_link import DEFAULT_DELAY_S, DEFAULT_MULTIPATH  # noqa: E402

ADDRESS = "127.0.0.11"


@pytest.fixture(scope="module")
def images(tmp_path_factory, shared_data):
    from PIL import Image

    folder = tmp_path_factory.mktemp("ota_images")
    Image.open(sorted((shared_data / "kodak").glob("*.png"))[0]).save(folder / "kodim01.png")
    return folder


def serve(snr_db: float, **kwargs) -> IiodServer:
    """An emulated Pluto whose own air is ``snr_db``; ``air_settable=False``: it behaves as a
    real board (its air is not the host's to set)."""
    board = EmulatedPluto.for_link(
        snr_db, seed=0, multipath=DEFAULT_MULTIPATH, delay_s=DEFAULT_DELAY_S, **kwargs
    )
    return IiodServer(board, ADDRESS, 0).serve_in_background()


def ota(tmp_path, images, *argv, radios=("pluto", "pluto")):
    out = tmp_path / "ota.json"
    args = ["ota", "--tx", radios[0], "--rx", radios[1], *argv, "--images", str(images)]
    args += ["--out", str(out), "--size", "48", "--max-images", "1", "--symbols-per-frame", "1024"]
    return main(args), out


def one_line_error(capsys, *words) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("osnerf ota: error: "), err
    assert all(w in err[0] for w in words), err[0]
    return err[0]


def _need_codec():
    semcodec = pytest.importorskip("semcodec")
    if not semcodec.DEFAULT_CHECKPOINT.is_file():
        pytest.skip("semcodec's shipped default checkpoint is not in this checkout")


# ----------------------------------------------------------------- the air of every path
def test_radios_pluto_measures_the_requested_snr(tmp_path, images):
    """The board's own air is 20 dB; the run asks for -10 dB and the receiver measures it;
    the result names both and the codec was told the air's SNR."""
    _need_codec()
    with serve(20.0) as srv:
        rc, out = ota(tmp_path, images, "--uri", srv.uri, "--schemes", "jscc", "--snr-db", "-10")
    assert rc == 0
    d = json.loads(out.read_text())
    r = d["results"][0]
    assert r["frames_lost"] == 0 and abs(r["snr_db_measured"] - -10.0) <= 1.5
    assert r["snr_db_requested"] == -10.0 and d["summary"]["snr_db_requested"] == -10.0
    assert d["codec"]["encoder_snr_db"] == -10.0 and d["config"]["air"] == "emulated"


def test_radios_pluto_air_takes_every_air_flag(tmp_path, images):
    """--multipath, --delay-us, --ppm and --seed reach the emulated Pluto's air, with the
    frames' power at --max-papr-db as its reference (the same AirChannel as the HackRFs')."""
    with serve(20.0) as srv:
        argv = ["--uri", srv.uri, "--schemes", "digital", "--snr-db", "12", "--multipath", "3:0.5"]
        argv += ["--delay-us", "7", "--ppm", "4,4", "--seed", "9", "--max-papr-db", "8"]
        rc, out = ota(tmp_path, images, *argv)
        board = srv.board
    assert rc == 0
    ch = board.medium.channel
    assert (ch.snr_db, ch.multipath, ch.delay_s) == (12.0, ((3, 0.5 + 0j),), 7e-6)
    assert ch.reference_power_dbfs == -8.0 and board.ppm == 4.0 and board.medium.seed == 9
    d = json.loads(out.read_text())
    assert d["config"]["ppm"] == "4,4" and d["results"][0]["snr_db_requested"] == 12.0


def test_radios_pluto_defaults_are_recorded_as_applied(tmp_path, images):
    """Without air flags the emulated Pluto gets the documented defaults, one crystal
    (ppm 0,0), and the record says so."""
    with serve(30.0) as srv:
        rc, out = ota(tmp_path, images, "--uri", srv.uri, "--schemes", "digital")
        board = srv.board
    assert rc == 0
    cfg = json.loads(out.read_text())["config"]
    assert (cfg["snr_db"], cfg["ppm"], cfg["delay_us"], cfg["seed"]) == (15.0, "0,0", 5.0, 0)
    assert board.medium.channel.snr_db == 15.0


def test_radios_pluto_refuses_ppm_apart(tmp_path, images, capsys):
    with serve(15.0) as srv:
        rc, out = ota(tmp_path, images, "--uri", srv.uri, "--schemes", "digital", "--ppm", "0,20")
    assert rc == 2 and not out.exists() and not (tmp_path / "ota_sigmf").exists()
    one_line_error(capsys, "--ppm", "one crystal")


def test_radios_emulated_hackrfs_record_requested_beside_measured(tmp_path, images):
    rc, out = ota(
        tmp_path, images, "--schemes", "digital", "--snr-db", "12", radios=("emulated",) * 2
    )
    assert rc == 0
    d = json.loads(out.read_text())
    r = d["results"][0]
    assert r["snr_db_requested"] == 12.0 and abs(r["snr_db_measured"] - 12.0) < 2.5
    assert d["summary"]["schemes"]["digital"]["snr_db_requested"] == 12.0


# ----------------------------------------------------------------- a real air
@pytest.mark.parametrize(
    "flag, value",
    [
        ("--snr-db", "-10"),
        ("--ppm", "1,1"),
        ("--multipath", "none"),
        ("--delay-us", "1"),
        ("--seed", "3"),
    ],
)
def test_radios_real_pluto_refuses_air_flags(tmp_path, images, capsys, flag, value):
    with serve(15.0, air_settable=False) as srv:
        rc, out = ota(tmp_path, images, "--uri", srv.uri, "--schemes", "digital", flag, value)
        assert srv.board.samples_received == 0  # refused before anything was sent
    assert rc == 2 and not out.exists() and not (tmp_path / "ota_sigmf").exists()
    one_line_error(capsys, flag, "real ADALM-Pluto")


def test_radios_real_hackrfs_refuse_snr_before_looking_for_boards(tmp_path, images, capsys):
    rc, out = ota(tmp_path, images, "--schemes", "digital", "--snr-db", "3", radios=("hackrf",) * 2)
    assert rc == 2 and not out.exists()
    one_line_error(capsys, "--snr-db", "real HackRF One")


def test_radios_real_pluto_jscc_encodes_at_the_measured_snr(tmp_path, images):
    """A real air: nothing requested; the encoder is told what a probe frame measured, and
    the result is labelled with the measured SNR only."""
    _need_codec()
    with serve(5.0, air_settable=False) as srv:
        rc, out = ota(tmp_path, images, "--uri", srv.uri, "--schemes", "jscc")
    assert rc == 0
    d = json.loads(out.read_text())
    r = d["results"][0]
    assert r["snr_db_requested"] is None and d["config"]["snr_db"] is None
    assert abs(d["codec"]["encoder_snr_db"] - 5.0) <= 1.5 and abs(r["snr_db_measured"] - 5.0) <= 1.5
    assert d["config"]["air"] == "real" and any("ota_probe_rx" in p for p in d["sigmf"])


# ----------------------------------------------------------------- ranges and URIs
@pytest.mark.parametrize("freq", ["6e9", "300e6"])
def test_radios_pluto_lo_range_at_the_command_line(tmp_path, images, capsys, freq):
    argv = ["--uri", "ip:127.0.0.1:1", "--schemes", "digital", "--center-freq-hz", freq]
    rc, out = ota(tmp_path, images, *argv)
    assert rc == 2 and not out.exists()
    one_line_error(capsys, "--center-freq-hz", "ADALM-Pluto", "[3.25e+08, 3.8e+09] Hz")


@pytest.mark.parametrize("uri", ["ip:", "ip::", "usb:1.2", "pluto", "ip:1.2.3.4:0", "ip:a b"])
def test_radios_malformed_uri_is_a_usage_error(tmp_path, images, capsys, uri):
    rc, out = ota(tmp_path, images, "--uri", uri, "--schemes", "digital")
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and not out.exists()
    assert err == [
        "osnerf ota: error: argument --uri: expected ip:HOST[:PORT], usb:[BUS.ADDR.INTF] or "
        f"local:, got {uri!r}"
    ]


def test_radios_close_destroys_the_context_while_the_error_lives():
    """A failed receive's error (what the CLI prints) still holds the driver's frames; after
    close no libiio context is left, so libiio's own lines come before the error line."""
    import iio

    with serve(15.0, fault="drop", after_samples=50_000) as srv:
        pluto = Pluto.open(srv.uri)
        with pytest.raises(HilError) as caught:
            pluto.rx(400_000)
        pluto.close()
        gc.collect()
        alive = [o for o in gc.get_objects() if type(o) is iio.Context]
        assert caught.value is not None and alive == []


# ----------------------------------------------------------------- leftovers and flags
def test_leftovers_overwrite_replaces_an_old_partial_capture(tmp_path, images, capsys):
    emulated = ("emulated",) * 2
    rc, _ = ota(tmp_path, images, "--schemes", "digital", "--fault", "unplug", radios=emulated)
    partial = sorted((tmp_path / "ota_sigmf").glob("ota_rx_partial.*"))
    assert rc == 1 and len(partial) == 2
    rc, out = ota(tmp_path, images, "--schemes", "digital", "--overwrite", radios=emulated)
    assert rc == 0
    left = sorted(p.name for p in (tmp_path / "ota_sigmf").iterdir())
    assert left == [f"ota_{d}.sigmf-{k}" for d in ("rx", "tx") for k in ("data", "meta")]
    assert sorted(json.loads(out.read_text())["sigmf"]) == [
        str(tmp_path / "ota_sigmf" / f"ota_{d}.sigmf-meta") for d in ("rx", "tx")
    ]


@pytest.mark.parametrize(
    "schemes, flag, value",
    [
        ("digital", "--codec", "nosuch"),
        ("digital", "--cbr", "1/8"),
        ("jscc", "--mcs", "16qam-1/2"),
        ("jscc", "--image-codec", "jpeg"),
        ("jscc", "--quality", "30"),
        ("jscc", "--scale", "2"),
    ],
)
def test_accept_refuses_flags_of_schemes_not_sent(tmp_path, images, capsys, schemes, flag, value):
    rc, out = ota(tmp_path, images, "--schemes", schemes, flag, value, radios=("emulated",) * 2)
    assert rc == 2 and not out.exists() and not (tmp_path / "ota_sigmf").exists()
    one_line_error(capsys, flag, f"--schemes {schemes}")


def test_accept_unused_scheme_flags_are_recorded_as_null(tmp_path, images):
    rc, out = ota(tmp_path, images, "--schemes", "digital", radios=("emulated",) * 2)
    cfg = json.loads(out.read_text())["config"]
    assert rc == 0 and cfg["cbr"] is None and cfg["codec"] is None and cfg["mcs"] == "qpsk-1/2"
    assert np.isfinite(json.loads(out.read_text())["results"][0]["psnr"])


def test_radios_pluto_refuses_max_overruns_it_cannot_count(tmp_path, images, capsys):
    rc, out = ota(
        tmp_path, images, "--uri", "ip:127.0.0.1:1", "--schemes", "digital", "--max-overruns", "5"
    )
    assert rc == 2 and not out.exists()
    one_line_error(capsys, "--max-overruns", "Pluto")


def test_radios_the_pluto_found_is_named_in_the_record(tmp_path, images, monkeypatch):
    with serve(15.0) as srv:
        monkeypatch.setenv("IIOD_REMOTE", f"{srv.address}:{srv.port}")
        rc, out = ota(tmp_path, images, "--schemes", "digital", "--snr-db", "20")
        board = srv.board
    assert rc == 0 and json.loads(out.read_text())["config"]["uri"] == srv.uri
    assert board.medium.channel.snr_db == 20.0


@pytest.mark.parametrize("settable, air", [(True, 3.0), (False, None)])
def test_radios_run_over_a_pluto_records_the_air_it_had(monkeypatch, settable, air):
    """``osnerf run``'s link over one Pluto: an emulated board's air is set to ``snr_db``; a
    real board's is nobody's to set, so the report says so and carries what the receiver
    measured instead of labelling the run with an SNR the air never had."""
    from types import SimpleNamespace

    import torch

    from osnerf.run.links import build_links

    cfg = SimpleNamespace(
        channel="ota",
        ota_device="pluto",
        snr_db=3.0,
        seed=0,
        ota_tx_args=None,
        ota_rx_args=None,
        ota_air="fixed",
    )
    with serve(12.0, air_settable=settable) as srv:
        monkeypatch.setenv("IIOD_REMOTE", f"{srv.address}:{srv.port}")
        links = build_links(cfg, None, [0])
        g = torch.Generator().manual_seed(0)
        bits = torch.randint(0, 4, (1, 1500), generator=g)
        x = torch.exp(1j * (torch.pi / 4 + torch.pi / 2 * bits)).to(torch.complex64)
        try:
            links.links[0](x, 3.0)
        finally:
            links.close()
    info = links.report.to_dict()
    assert info["air_snr_db"] == air and info["frames_lost"] == 0
    assert abs(info["snr_db_measured"] - (3.0 if settable else 12.0)) < 1.5
    assert ("note" in info) is (not settable)
