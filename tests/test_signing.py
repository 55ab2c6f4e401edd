"""The signing key (wire/signing.py) and its command-line option on every command: a good key loads
from ``--signing-key FILE`` or ``WINDSEEK_SIGNING_KEY``, a bad one gives one clear line naming its
source and never the key, and the key shows nowhere (repr, errors, output)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from wire import signing

KEY_HEX = "3f" * 16 + "a1b2c3d4e5f60718293a4b5c6d7e8f90"  # 64 hex characters, a 32-byte key
ROOT = Path(__file__).resolve().parents[1]


def test_key_from_file_env_and_precedence(tmp_path: Path) -> None:
    f = tmp_path / "key.hex"
    f.write_text(KEY_HEX.upper() + "\n")
    k = signing.load_key(str(f), environ={})
    assert k is not None and k.secret == bytes.fromhex(KEY_HEX) and k.source == f"file {f}"
    other = "11" * 32
    e = signing.load_key(None, environ={signing.ENV_VAR: other})
    assert e is not None and e.secret == bytes.fromhex(other)
    assert signing.load_key(str(f), environ={signing.ENV_VAR: other}).secret == bytes.fromhex(KEY_HEX)
    assert signing.load_key(None, environ={}) is None
    # The key never shows in its representation.
    for text in (repr(k), str(k), f"{k}", repr([k])):
        assert KEY_HEX not in text.lower() and "3f3f" not in text


@pytest.mark.parametrize(("content", "why"), [
    ("3f" * 31, "expected 64 hexadecimal characters"),
    ("3f" * 33, "expected 64 hexadecimal characters"),
    ("zz" + "3f" * 31, "only hexadecimal characters"),
    ("00" * 32, "all-zero key"),
])  # fmt: skip
def test_bad_key_says_why_without_the_key(tmp_path: Path, content: str, why: str) -> None:
    f = tmp_path / "key.hex"
    f.write_text(content)
    with pytest.raises(signing.SigningKeyError) as ei:
        signing.load_key(str(f), environ={})
    msg = str(ei.value)
    assert why in msg and str(f) in msg and content not in msg and "\n" not in msg


def test_unreadable_key_file(tmp_path: Path) -> None:
    with pytest.raises(signing.SigningKeyError, match="cannot read it"):
        signing.load_key(str(tmp_path / "missing.hex"), environ={})
    with pytest.raises(signing.SigningKeyError, match=r"environment variable WINDSEEK_SIGNING_KEY"):
        signing.load_key(None, environ={signing.ENV_VAR: "abc"})


@pytest.mark.parametrize("command", [
    ["sitl", "open-field", "--no-udp", "--tcp", "0"],
    ["estimator", "--connect", "udpin://127.0.0.1:9"],
    ["mission", "--connect", "udpin://127.0.0.1:9", "--strategy", "surge-cast"],
])  # fmt: skip
def test_every_command_refuses_a_bad_key_in_one_line(tmp_path: Path, command: list[str]) -> None:
    bad = "ab" * 31 + "0"  # 63 characters
    f = tmp_path / "key.hex"
    f.write_text(bad)
    res = subprocess.run([sys.executable, "-m", "windseek.cli", *command, "--signing-key", str(f)],
                         capture_output=True, text=True, timeout=120, cwd=ROOT)  # fmt: skip
    assert res.returncode != 0
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "expected 64 hexadecimal characters" in lines[0], res.stderr
    assert bad not in res.stderr + res.stdout and "Traceback" not in res.stderr
    # The environment variable is refused the same way.
    env = {"WINDSEEK_SIGNING_KEY": bad, "PATH": "/usr/bin:/bin"}
    res = subprocess.run([sys.executable, "-m", "windseek.cli", *command], capture_output=True, text=True,
                         timeout=120, cwd=ROOT, env=env)  # fmt: skip
    assert res.returncode != 0 and "WINDSEEK_SIGNING_KEY" in res.stderr and bad not in res.stderr
