"""Smoke test of ``python -m benchmarks.studies.soak``: a few episodes, the per-episode records and the summary written."""

from __future__ import annotations

import json

from benchmarks.studies import soak


def test_soak_smoke(tmp_path) -> None:
    report = soak.main(["--episodes", "3", "--env", "Pendulum-v1", "--output", str(tmp_path)])
    data = json.loads((tmp_path / "soak.json").read_text())
    assert len(data["rss_mib"]) == 3 and len(data["update_s"]) == 3
    assert all(value > 10 for value in data["rss_mib"]) and all(value > 0 for value in data["update_s"])
    assert data["summary"]["episodes"] == 3 and data["summary"]["window"] == 1
    assert data["summary"]["rss_mib_median_last"] == data["rss_mib"][-1]
    assert "commit" in data["git"] and data["machine"]["nproc"] >= 1
    assert "| resident memory (MiB) |" in (tmp_path / "soak.md").read_text()
    assert report["summary"] == data["summary"]


def test_rss_reads_proc() -> None:
    before = soak.rss_mib()
    block = bytearray(64 * 2**20)  # 64 MiB touched
    block[::4096] = b"\x01" * len(block[::4096])
    assert soak.rss_mib() - before > 50
    del block
