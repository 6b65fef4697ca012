"""Where the operator opens a device's page (the XR page): its URL and a QR code, printed once the device
has started serving it."""

from __future__ import annotations

import time
from collections.abc import Iterable

from teleprev.devices import Device


def has_page(device: Device) -> bool:
    return type(device).operator_urls is not Device.operator_urls


def announce_pages(console, devices: Iterable[Device], wait_s: float = 5.0) -> list[str]:
    """Print each page's URL(s) with a QR code (for a headset's camera), waiting up to wait_s for the
    devices to start serving; the URLs printed."""
    import segno

    paged = [d for d in devices if has_page(d)]
    deadline = time.monotonic() + wait_s
    while paged and not all(d.operator_urls() for d in paged) and time.monotonic() < deadline:
        time.sleep(0.05)
    printed: list[str] = []
    for device in paged:
        for url in device.operator_urls():
            if url in printed:
                continue
            printed.append(url)
            console.print(f"XR page: open [bold]{url}[/] in the headset's browser", highlight=False, soft_wrap=True)
            if url.startswith("https://127.0.0.1:"):
                port = url.split(":")[2].split("/")[0]
                console.print(
                    f"  (a Quest on USB reaches it after `adb reverse tcp:{port} tcp:{port}`)", highlight=False
                )
            segno.make(url, error="l").terminal(out=console.file, compact=True)
    return printed
