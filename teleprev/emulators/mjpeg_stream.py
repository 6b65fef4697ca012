"""A network camera as IP cameras serve one: HTTP multipart MJPEG (`multipart/x-mixed-replace`), written with
the standard library, for opencv.camera to read over a real socket.

    with MjpegServer(fps=30).start() as cam:      # cam.url: http://127.0.0.1:<port>/stream.mjpg
        ...
        cam.inject("stall", seconds=2.0)          # the stream stops sending, the connection stays open
        cam.inject("end")                          # every open stream ends (the camera rebooted)

Each frame shows a white square that moves one step per frame over a dark background, and the frame's
number in the first row of pixels' blue channel (frame % 256), so a reader can tell frames apart.
"""

from __future__ import annotations

import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np

BOUNDARY = "teleprevframe"
FAULTS = ("stall", "end")


def pattern(index: int, width: int, height: int) -> np.ndarray:
    frame = np.full((height, width, 3), 40, np.uint8)
    side = max(4, height // 4)
    x = (index * 4) % max(1, width - side)
    frame[height // 2 - side // 2: height // 2 + side // 2, x:x + side] = 255
    frame[0, :, 0] = index % 256
    return frame


class MjpegServer:
    def __init__(self, fps: float = 30.0, width: int = 160, height: int = 120, host: str = "127.0.0.1", port: int = 0):
        import cv2

        self.fps, self.width, self.height = fps, width, height
        self._jpegs = [cv2.imencode(".jpg", pattern(i, width, height), [cv2.IMWRITE_JPEG_QUALITY, 90])[1].tobytes()
                       for i in range(64)]
        self._stall_until = 0.0
        self._generation = 0  # bumped by "end": streams of an older generation stop
        self._lock = threading.Lock()
        self.frames_sent = 0
        self.clients = 0
        server = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):  # quiet
                pass

            def do_GET(self):
                if self.path.split("?")[0] != "/stream.mjpg":
                    self.send_error(404)
                    return
                server._stream(self)

        self._httpd = ThreadingHTTPServer((host, port), Handler)
        self._httpd.daemon_threads = True
        self.url = f"http://{host}:{self._httpd.server_address[1]}/stream.mjpg"
        self._thread = threading.Thread(target=self._httpd.serve_forever, kwargs={"poll_interval": 0.05},
                                        name="emulator-mjpeg", daemon=True)

    def start(self) -> MjpegServer:
        self._thread.start()
        return self

    def stop(self) -> None:
        with self._lock:
            self._generation += 1
        self._httpd.shutdown()
        self._httpd.server_close()
        self._thread.join(2.0)

    def __enter__(self) -> MjpegServer:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def rig_keys(self, name: str = "cam") -> str:
        return f'[devices.{name}]\nplugin = "opencv.camera"\nsource = "{self.url}"\n'

    def inject(self, kind: str, seconds: float = 2.0) -> None:
        with self._lock:
            if kind == "stall":
                self._stall_until = time.monotonic() + seconds
            elif kind == "end":
                self._generation += 1
            else:
                raise ValueError(f"unknown fault {kind!r} (one of {', '.join(FAULTS)})")

    def _stream(self, handler: BaseHTTPRequestHandler) -> None:
        with self._lock:
            generation = self._generation
            self.clients += 1
        handler.send_response(200)
        handler.send_header("Content-Type", f"multipart/x-mixed-replace; boundary={BOUNDARY}")
        handler.send_header("Cache-Control", "no-cache")
        handler.end_headers()
        period = 1.0 / self.fps
        next_t = time.monotonic()
        index = 0
        try:
            while True:
                with self._lock:
                    if generation != self._generation:
                        return
                    stalled = time.monotonic() < self._stall_until
                if not stalled:
                    jpeg = self._jpegs[index % len(self._jpegs)]
                    handler.wfile.write(f"--{BOUNDARY}\r\nContent-Type: image/jpeg\r\nContent-Length: {len(jpeg)}"
                                        "\r\n\r\n".encode() + jpeg + b"\r\n")
                    handler.wfile.flush()
                    index += 1
                    with self._lock:
                        self.frames_sent += 1
                next_t += period
                time.sleep(max(0.0, next_t - time.monotonic()))
                next_t = max(next_t, time.monotonic() - period)
        except OSError:  # the reader went away
            return
