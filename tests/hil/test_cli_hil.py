"""`osnerf hil info --emulate` prints what hackrf_info prints."""

from osnerf.cli import main


def test_hil_info_emulated(capsys):
    assert main(["hil", "info", "--emulate"]) == 0
    out = capsys.readouterr().out
    assert out.count("Found HackRF") == 2
    assert "Serial number: 000000000000000057b068dc1f2e3d40" in out
    assert "Board ID Number: 2 (HackRF One)" in out
    assert "Firmware Version: 2024.02.1 (API:1.08)" in out
    assert "Part ID Number: 0xa000cb3c 0x00574f61" in out


def test_hil_info_serial_filter_and_bad_action(capsys):
    assert main(["hil", "info", "--emulate", "--serial", "3d41"]) == 0
    out = capsys.readouterr().out
    assert out.count("Found HackRF") == 1 and "3d41" in out
    assert main(["hil", "flash"]) == 2
