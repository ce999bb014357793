"""The training campaign (python -m campaign): a stretch continues a line from its best and
accumulates, a moved reference is refused, and promotion follows its stated rule."""

import json
from pathlib import Path

from smooth_images import write_images

from campaign.__main__ import main
from campaign.promotion import RULE, decide

ROOT = Path(__file__).resolve().parents[2]


def test_continue_runs_two_learning_rates_and_accumulates(tiny_campaign):
    camp, argv = tiny_campaign
    assert main(argv) == 0
    first = json.loads((camp / "campaign.json").read_text())["lines"]["tiny"]
    log = [json.loads(s) for s in (camp / "log.jsonl").read_text().splitlines()]
    assert [r["lr"] for r in log] == [1e-3, 5e-4]  # both learning rates, both logged
    assert [r["steps"] for r in log] == [6, 6]
    assert sum(r["kept"] for r in log) == 1  # from scratch: the better one becomes the best
    won = next(r for r in log if r["kept"])
    assert won["score"] == max(r["score"] for r in log)
    assert all(r["cpu_minutes"] > 0 and r["device_minutes"] == 0 for r in log)
    assert first["best"]["sha256"] == won["sha256"]
    assert (camp / first["best"]["path"]).is_file()
    assert first["stretches"] == 1 and first["steps"] == 6
    assert won["lr"] in first["lrs"] and len(set(first["lrs"])) == 2

    assert main(argv) == 0  # the second call continues from where the first left
    second = json.loads((camp / "campaign.json").read_text())["lines"]["tiny"]
    log = [json.loads(s) for s in (camp / "log.jsonl").read_text().splitlines()]
    assert len(log) == 4
    assert [r["stretch"] for r in log[2:]] == [1, 1]
    assert all(r["init_sha256"] == won["sha256"] for r in log[2:])
    assert [r["lr"] for r in log[2:]] == first["lrs"]
    assert {r["seed"] for r in log[2:]}.isdisjoint({r["seed"] for r in log[:2]})
    assert all(r["line_steps"] == 12 for r in log[2:])
    assert second["stretches"] == 2
    if any(r["kept"] for r in log[2:]):
        assert second["steps"] == 12 and second["best"]["sha256"] != won["sha256"]
    else:
        assert second["best"]["sha256"] == won["sha256"]


def test_continue_refuses_a_moved_reference(tiny_campaign, tmp_path, tiny_ckpt, capsys):
    camp, argv = tiny_campaign
    doc = json.loads((camp / "campaign.json").read_text())
    doc["lines"]["tiny"]["best"] = {"path": str(tiny_ckpt), "sha256": "0" * 64}
    (camp / "campaign.json").write_text(json.dumps(doc))
    assert main(argv) == 2
    assert "recorded 000000000000" in capsys.readouterr().err
    assert not (camp / "log.jsonl").exists() and not (tmp_path / "work").exists()


def _points(deltas):
    return [
        {"channel": "awgn", "cbr": "1/16", "snr_db": float(i), "candidate": 25 + d, "baseline": 25}
        for i, d in enumerate(deltas)
    ]


def test_promotion_rule():
    ota = [{"snr_db": 1.0, "seed": s, "candidate": 20.0, "baseline": 20.0} for s in range(5)]
    assert decide(_points([0.3, 0.2, 0.25]), ota)["promote"]
    worse = decide(_points([0.8, 0.8, -0.15]), ota)  # one point too far below, mean high
    assert not worse["promote"] and "0.15 dB below" in worse["reasons"][0]
    assert not decide(_points([0.1, 0.15, 0.2]), ota)["promote"]  # mean gain 0.15 < 0.2
    assert decide(_points([-RULE["max_loss_db"], 0.4, 0.4]), ota)["promote"]  # at the limit
    air = [{**p, "candidate": 19.8} for p in ota]
    assert not decide(_points([0.3, 0.3, 0.3]), air)["promote"]  # worse over the air


def test_promote_dry_run_writes_the_comparison(tmp_path, tiny_ckpt):
    images = write_images(tmp_path / "kodak", 2, 32, 7)
    argv = ["promote", str(tiny_ckpt), "--baseline", str(tiny_ckpt), "--images", str(images)]
    argv += ["--channels", "awgn", "--cbrs", "1/16", "--snrs-db", "10", "--ota-seeds", "0"]
    argv += ["--ota-snrs-db", "10", "--ota-size", "32", "--out", str(tmp_path), "--dry-run"]
    assert main(argv) == 0
    (path,) = tmp_path.glob("promotion_*.json")
    doc = json.loads(path.read_text())
    assert doc["promoted"] is False
    assert doc["decision"]["mean_gain_db"] == 0.0  # the same codec: no gain
    assert doc["decision"]["reasons"] == ["mean gain +0.00 dB < 0.2 dB"]
    assert len(doc["kodak"]) == 1 and len(doc["ota"]) == 1
    assert doc["candidate"]["sha256"] == doc["baseline"]["sha256"]
