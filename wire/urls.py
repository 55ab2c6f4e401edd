"""Connection URLs: MAVSDK's forms (``udpin://HOST:PORT`` ...) to pymavlink's, for every program."""

from __future__ import annotations


def pymavlink_url(url: str) -> tuple[str, int]:
    """A MAVSDK-style URL to a pymavlink device string and baud rate (pymavlink forms pass through)."""
    for pre, rep in (("udpin://", "udpin:"), ("udpout://", "udpout:"), ("udp://", "udpin:"),
                     ("tcpout://", "tcp:"), ("tcp://", "tcp:"), ("tcpin://", "tcpin:")):  # fmt: skip
        if url.startswith(pre):
            return rep + url[len(pre):], 115200
    if url.startswith("serial://"):
        dev, sep, baud = url[len("serial://"):].rpartition(":")
        return (dev, int(baud)) if sep and baud.isdigit() else (url[len("serial://"):], 57600)
    if url.startswith("/dev/") or url.startswith("COM"):
        dev, sep, baud = url.rpartition(":")
        return (dev, int(baud)) if sep and baud.isdigit() else (url, 57600)
    if url.split(":", 1)[0] in ("udpin", "udpout", "udpbcast", "tcp", "tcpin"):
        return url, 115200
    raise ValueError(f"--connect {url!r}: expected udpin://HOST:PORT, udpout://HOST:PORT, tcpout://HOST:PORT, "
                     "tcpin://HOST:PORT or serial:///dev/DEVICE:BAUD")
