"""Regenerate ``windseek.py`` (the dialect's Python module) from ``windseek.xml`` with pymavlink's mavgen.

Run ``python -m wire.dialect.generate`` after editing the XML; the generated module is committed
so importing the package never needs a code generator at run time.
"""

from __future__ import annotations

from pathlib import Path


def generate() -> Path:
    """Generate the MAVLink 2 Python module next to the XML; returns its path."""
    from pymavlink.generator import mavgen

    here = Path(__file__).resolve().parent
    out = here / "windseek"
    opts = mavgen.Opts(str(out), wire_protocol="2.0", language="Python3", validate=False)
    ok = mavgen.mavgen(opts, [str(here / "windseek.xml")])
    if not ok:
        raise RuntimeError("mavgen failed on windseek.xml")
    py = out.with_suffix(".py")
    # Generated code is not ours to lint; mark it so ``ruff check`` skips it.
    text = py.read_text()
    if not text.startswith("# ruff: noqa"):
        py.write_text("# ruff: noqa\n" + text)
    return py


if __name__ == "__main__":
    print(generate())
