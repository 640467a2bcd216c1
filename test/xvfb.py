"""A private Xvfb display for GUI tests, and screenshots read from its framebuffer file."""
import os
from pathlib import Path
import select
import shutil
import struct
import subprocess
import time

import numpy as np
import pytest

SKIP_REASON = ('Xvfb is not installed (Debian package xvfb, with libgl1-mesa-dri for OpenGL; '
               '.ci/run installs them best effort)')


class Xvfb:
    """
    An X server in memory (``Xvfb``) on a display number it picks itself (``-displayfd``).

    No TCP listener; clients connect through the local socket. ``-fbdir`` makes it keep its
    screen in an XWD file, so a screenshot is a file read, with no other X tool.
    """

    def __init__(self, fb_dir: Path, width: int = 1024, height: int = 768,
                 timeout_s: float = 20.0) -> None:
        exe = shutil.which('Xvfb')
        if exe is None:
            pytest.skip(SKIP_REASON)
        self.fb_file = Path(fb_dir) / 'Xvfb_screen0'
        # Xvfb writes 'N\n' to this pipe when it is ready (maybe in pieces); the read end stays
        # open while it runs, as a write to a closed pipe would kill it.
        self._read_fd, write_fd = os.pipe()
        try:
            self.proc = subprocess.Popen(
                [exe, '-displayfd', str(write_fd), '-screen', '0', f'{width}x{height}x24',
                 '-fbdir', str(fb_dir), '-nolisten', 'tcp'],
                pass_fds=(write_fd,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                start_new_session=True)
        finally:
            os.close(write_fd)
        text, deadline = b'', time.monotonic() + timeout_s
        while not text.endswith(b'\n') and time.monotonic() < deadline:
            ready, _, _ = select.select([self._read_fd], [], [], 0.5)
            chunk = os.read(self._read_fd, 64) if ready else b''
            if ready and not chunk:
                break  # Xvfb exited
            text += chunk
        number = text.decode().strip()
        if not text.endswith(b'\n') or not number.isdigit():
            self.close()
            raise RuntimeError(f'Xvfb gave no display number within {timeout_s} s '
                               f'(got {text!r}, exit code {self.proc.poll()})')
        self.display = f':{number}'

    def env(self, base=None) -> dict:
        """Return an environment whose X clients open their windows on this display."""
        env = dict(os.environ if base is None else base)
        env['DISPLAY'] = self.display
        return env

    def screenshot(self) -> np.ndarray:
        """Return the screen as an (height, width, 3) uint8 RGB array (XWD, 24/32 bpp)."""
        data = self.fb_file.read_bytes()
        header = struct.unpack('>25I', data[:100])
        header_size, width, height = header[0], header[4], header[5]
        byte_order, bits_per_pixel = header[7], header[11]
        bytes_per_line, ncolors = header[12], header[19]
        if bits_per_pixel != 32:
            raise ValueError(f'expected 32 bits per pixel, got {bits_per_pixel}')
        offset = header_size + 12 * ncolors
        pixels = np.frombuffer(data, np.uint8, bytes_per_line * height, offset)
        pixels = pixels.reshape(height, bytes_per_line // 4, 4)[:, :width]
        # LSBFirst (0): bytes B, G, R, pad per pixel; MSBFirst: pad, R, G, B.
        return pixels[:, :, [2, 1, 0]].copy() if byte_order == 0 else pixels[:, :, 1:].copy()

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self._read_fd >= 0:
            os.close(self._read_fd)
            self._read_fd = -1
