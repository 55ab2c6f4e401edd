"""A truncated DataFlash ``.bin`` or ULog is reviewed with a warning that it is cut off (issue 31, finding 3),
as the tlog reader does ("the last record is cut off (a truncated log)"): on stderr, in the summary's
``warning:`` lines and in the JSON's ``warnings``. The cut files are the first 60 % of real shared logs.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from pymavlink.DFReader import DFReader_binary

from windseek.cli import main as cli_main

_LOGS = [Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "logs", Path("/work/shared/data/logs")]
LOGS = next((p.resolve() for p in _LOGS if (p / "SOURCES.md").is_file()), None)
pytestmark = pytest.mark.skipif(LOGS is None, reason="third-party logs not found at ../shared/data/logs")
CUT = "the last message is cut off (a truncated log)"


def _cut(tmp_path: Path, name: str, fraction: float) -> Path:
    assert LOGS is not None
    data = (LOGS / name).read_bytes()
    out = tmp_path / f"cut-{name}"
    out.write_bytes(data[: int(len(data) * fraction)])
    return out


def _review(path: Path, capsys: pytest.CaptureFixture, *json_flag: str,
            out: Path | None = None) -> tuple[int, str, str]:  # fmt: skip
    rc = cli_main(["review", str(path), "-o", str(out or path.with_suffix(".rrd")), *json_flag])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


@pytest.mark.parametrize("name", ["px4-sitl-quad-hover.ulg", "ardupilot-dataflash-excerpt.BIN"])
def test_truncated_log_is_reviewed_with_a_warning(name: str, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    cut = _cut(tmp_path, name, 0.6)
    rc, out, err = _review(cut, capsys)
    assert rc == 0  # still reviewed: 60 % of a log is data worth showing
    assert f"windseek review: warning: {cut}: {CUT}" in err.splitlines(), err
    assert f"warning: {CUT}" in out.splitlines(), out
    rc, out, _ = _review(cut, capsys, "--json")
    assert rc == 0 and CUT in json.loads(out)["warnings"]


def test_whole_ulog_and_dataflash_cut_at_a_message_boundary_have_no_warning(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:  # fmt: skip
    """The warning is about the file's end, not the kind of log: a whole ULog has none, nor a DataFlash
    log cut exactly after a complete message (the shared excerpt itself ends inside one: 64 KiB)."""
    assert LOGS is not None
    _, out, _ = _review(LOGS / "px4-sitl-quad-hover.ulg", capsys, "--json", out=tmp_path / "a.rrd")
    assert json.loads(out)["warnings"] == []
    src = LOGS / "ardupilot-dataflash-excerpt.BIN"
    r = DFReader_binary(str(src), zero_time_base=False)
    last = max(int(offs[-1]) for offs in r.offsets if len(offs))  # the excerpt's last message, cut by 64 KiB
    whole = tmp_path / "boundary.BIN"
    whole.write_bytes(src.read_bytes()[:last])
    _, out, _ = _review(whole, capsys, "--json")
    assert json.loads(out)["warnings"] == []
    _, out, _ = _review(src, capsys, "--json", out=tmp_path / "b.rrd")
    assert CUT in json.loads(out)["warnings"]
