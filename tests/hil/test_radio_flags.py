"""`osnerf ota`'s flags for SoapySDR devices and GNU Radio flowgraphs: refused in one line
(exit 2) where they cannot apply, before anything is opened."""

import pytest

from osnerf.cli import main


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--tx", "zmq", "--rx", "zmq"], "zmq:ENDPOINT"),
        (
            ["--tx", "emulated", "--rx", "emulated", "--tx-args", "driver=uhd"],
            "--tx-args/--rx-args need --tx soapy",
        ),
        (["--tx", "soapy:driver=uhd", "--rx", "soapy"], "name the devices with --tx-args"),
        (["--tx", "zmq:tcp://127.0.0.1:5555", "--rx", "soapy"], "--tx and --rx must both be"),
        (["--tx", "emulated", "--rx", "emulated", "--tx-gain-db", "10"], "need --tx soapy"),
    ],
)
def test_device_flags_are_checked_first(tmp_path, capsys, argv, message):
    out = tmp_path / "ota.json"
    rc = main(["ota", *argv, "--schemes", "digital", "--images", str(tmp_path), "--out", str(out)])
    assert rc == 2 and message in capsys.readouterr().err and not out.exists()


def test_the_run_config_holds_every_flag_in_help_order_then_the_air():
    """`osnerf ota` reads its flags once, into ``OtaRunConfig``, whose fields are the result
    file's ``config``: every flag of the parser, in its order, then ``air``."""
    import dataclasses

    from osnerf.cli import build_parser
    from osnerf.commands.ota_config import OtaRunConfig

    argv = ["ota", "--schemes", "digital", "--images", "x", "--out", "o.json"]
    args = build_parser("ota").parse_args(argv)
    flags = [k for k in vars(args) if k != "command"]
    assert [f.name for f in dataclasses.fields(OtaRunConfig)] == [*flags, "air"]
    opts = OtaRunConfig.from_args(args, air="real")
    assert opts.as_record() == {**{k: vars(args)[k] for k in flags}, "air": "real"}
    with pytest.raises(dataclasses.FrozenInstanceError):
        opts.snr_db = 3.0  # type: ignore[misc]
