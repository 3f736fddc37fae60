"""Frames of the penny: a small numpy rasterizer ("rgb_array") and a pygame-ce window ("human").

The frame shows the table (inside light, outside dark, the wall as a line, the marked arc of
the impacts task in orange), the target (blue disc), the trail of the contact point (grey dots)
and the penny seen from above: a black segment between its two ends with its front end marked
by a red disc. y points up. Impacts flash: a yellow ring around each impact point, widening and
fading over FLASH_INTERVALS control intervals of simulated time. A text line at the top left
shows the simulated time, the last step's reward and the episode's impact count. pygame is
imported only by the "human" mode, which initialises pygame's display and nothing else (no audio).

What the env passes (``Renderer.draw(state, target, trail, arc, hud)``), ``hud`` a dict, every key
optional: ``time`` (simulated time [s]), ``reward`` (the last step's reward), ``impact_count``
(impacts since the reset) and ``impacts``, the recent impacts as ``(time [s], end (+1 front / -1
back), state at the impact)`` with times on the same clock as ``time``.
"""
from __future__ import annotations

import math
import os
import warnings

import numpy as np

# the frame's colours (RGB)
(INSIDE, OUTSIDE, PLANE, GRID, WALL, ARC, TARGET, TRAIL, PENNY, FRONT, FLASH, TEXT, TEXT_BOX) = (
    np.array(rgb, np.uint8) for rgb in ((236, 242, 228), (70, 74, 82), (245, 245, 245), (225, 225, 225), (30, 30, 30),
                                        (255, 150, 0), (40, 90, 230), (150, 150, 170), (0, 0, 0), (220, 30, 30),
                                        (255, 215, 0), (255, 255, 255), (20, 20, 28)))

FLASH_INTERVALS = 4  # an impact's ring fades out over this many control intervals of simulated time

# A 3 x 5 pixel font for the text line, drawn 2x: a character, then its rows top to bottom ("#" set; "_" is the space)
_FONT = """
0 ### #.# #.# #.# ###
1 .#. ##. .#. .#. ###
2 ### ..# ### #.. ###
3 ### ..# ### ..# ###
4 #.# #.# ### ..# ..#
5 ### #.. ### ..# ###
6 ### #.. ### #.# ###
7 ### ..# ..# ..# ..#
8 ### #.# ### #.# ###
9 ### #.# ### ..# ###
. ... ... ... ... .#.
- ... ... ### ... ...
+ ... .#. ### .#. ...
_ ... ... ... ... ...
A .#. #.# ### #.# #.#
C .## #.. #.. #.. .##
D ##. #.# #.# #.# ##.
E ### #.. ##. #.. ###
F ### #.. ##. #.. #..
I ### .#. .#. .#. ###
M #.# ### ### #.# #.#
N ##. #.# #.# #.# #.#
P ##. #.# ##. #.. #..
R ##. #.# ##. #.# #.#
S .## #.. .#. ..# ##.
T ### .#. .#. .#. .#.
W #.# #.# #.# ### #.#
"""
_GLYPHS = {(line[0] if line[0] != "_" else " "): tuple(line[2:].split()) for line in _FONT.strip().split("\n")}
_GLYPH_MASKS = {c: np.array([[ch == "#" for ch in row] for row in g]) for c, g in _GLYPHS.items()}
TEXT_SCALE = 2

_warned_no_display = False


def hud_text(hud: dict) -> str:
    """The text line for a hud dict (see the module docstring)."""
    parts = []
    if "time" in hud:
        parts.append(f"T {hud['time']:.2f} S")
    if "reward" in hud:
        parts.append(f"REWARD {hud['reward']:+.3f}")
    if "impact_count" in hud:
        parts.append(f"IMPACTS {int(hud['impact_count'])}")
    return "   ".join(parts).upper()


def _has_display() -> bool:
    """Whether SDL can open a visible window here (a dummy/offscreen driver or no X/Wayland: no)."""
    driver = os.environ.get("SDL_VIDEODRIVER", "")
    if driver in ("dummy", "offscreen"):
        return False
    if os.name == "posix" and not os.uname().sysname == "Darwin":
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")) or driver not in ("", "x11", "wayland")
    return True



class _Arc:
    """The one field of an env's state that a task's marked_arc reads (the renderer has no other state)."""

    def __init__(self, arc):
        self.arc = arc

class Renderer:
    """Draws frames for one env; ``width`` pixels across the view."""

    def __init__(self, core, mode: str, fps: int = 20, width: int = 480):
        self.core = core
        self.mode = mode
        self.fps = fps
        if core.plane:
            h = 1.5 * core.scene.arena
            self.x0, self.x1, self.y0, self.y1 = -h, h, -h, h
        else:
            xmin, xmax, ymin, ymax = core.table.extent
            pad = 0.06 * max(xmax - xmin, ymax - ymin)
            self.x0, self.x1, self.y0, self.y1 = xmin - pad, xmax + pad, ymin - pad, ymax + pad
        self.scale = width / (self.x1 - self.x0)  # pixels per metre
        self.W = int(width)
        self.H = int(round((self.y1 - self.y0) * self.scale))
        self._background = self._make_background()
        self._arc_for = None
        self._arc_bg = None
        self.window = None
        self.clock = None

    # world <-> pixel: column = (x - x0) * scale, row = (y1 - y) * scale (pixel centres at +0.5)
    def to_pixel(self, x, y):
        """(row, col) integer pixel containing the world point (x, y)."""
        return int(math.floor((self.y1 - y) * self.scale)), int(math.floor((x - self.x0) * self.scale))

    def _grid(self):
        cols = (np.arange(self.W) + 0.5) / self.scale + self.x0
        rows = self.y1 - (np.arange(self.H) + 0.5) / self.scale
        return np.meshgrid(cols, rows)

    def _make_background(self):
        img = np.empty((self.H, self.W, 3), np.uint8)
        X, Y = self._grid()
        if self.core.plane:
            img[:] = PLANE
            step = 0.05
            gx = np.abs(X / step - np.round(X / step)) * step * self.scale < 0.5
            gy = np.abs(Y / step - np.round(Y / step)) * step * self.scale < 0.5
            img[gx | gy] = GRID
            return img
        h = self.core.table.h(X, Y)
        img[:] = OUTSIDE
        img[h < 0] = INSIDE
        # the wall: pixels whose centre is within ~1 pixel of {h = 0} (|grad h| <= grad_bound)
        gx, gy = self.core.table.grad(X, Y)
        dist = np.abs(h) / np.maximum(np.hypot(gx, gy), 1e-12)
        img[dist * self.scale < 1.0] = WALL
        return img

    def _background_with_arc(self, arc):
        marked = self.core.task_record.marked_arc
        if self.core.plane or marked is None:
            return self._background
        _, _, cos_hw = marked(self.core.k, _Arc(tuple(arc)))  # (the task's own marked arc: its half-width)
        if cos_hw < -1.0:  # the whole wall counts
            return self._background
        if self._arc_for != arc:
            img = self._background.copy()
            X, Y = self._grid()
            h = self.core.table.h(X, Y)
            gx, gy = self.core.table.grad(X, Y)
            dist = np.abs(h) / np.maximum(np.hypot(gx, gy), 1e-12)
            cb, sb = arc
            on = X * cb + Y * sb >= cos_hw * np.hypot(X, Y)
            img[(dist * self.scale < 2.5) & on] = ARC
            self._arc_for, self._arc_bg = arc, img
        return self._arc_bg

    def _disc(self, img, x, y, radius_px, color):
        cx, cy = (x - self.x0) * self.scale, (self.y1 - y) * self.scale
        r = radius_px
        c0, c1 = max(int(cx - r) - 1, 0), min(int(cx + r) + 2, self.W)
        r0, r1 = max(int(cy - r) - 1, 0), min(int(cy + r) + 2, self.H)
        if c0 >= c1 or r0 >= r1:
            return
        cc, rr = np.meshgrid(np.arange(c0, c1) + 0.5, np.arange(r0, r1) + 0.5)
        m = (cc - cx) ** 2 + (rr - cy) ** 2 <= r * r
        img[r0:r1, c0:c1][m] = color

    def _segment(self, img, xa, ya, xb, yb, half_px, color):
        ax, ay = (xa - self.x0) * self.scale, (self.y1 - ya) * self.scale
        bx, by = (xb - self.x0) * self.scale, (self.y1 - yb) * self.scale
        c0 = max(int(min(ax, bx) - half_px) - 1, 0)
        c1 = min(int(max(ax, bx) + half_px) + 2, self.W)
        r0 = max(int(min(ay, by) - half_px) - 1, 0)
        r1 = min(int(max(ay, by) + half_px) + 2, self.H)
        if c0 >= c1 or r0 >= r1:
            return
        cc, rr = np.meshgrid(np.arange(c0, c1) + 0.5, np.arange(r0, r1) + 0.5)
        dx, dy = bx - ax, by - ay
        L2 = dx * dx + dy * dy
        t = np.clip(((cc - ax) * dx + (rr - ay) * dy) / L2, 0.0, 1.0) if L2 > 0 else 0.0
        m = (cc - ax - t * dx) ** 2 + (rr - ay - t * dy) ** 2 <= half_px * half_px
        img[r0:r1, c0:c1][m] = color

    def _ring(self, img, x, y, r_px, half_px, color, alpha):
        """Blend an annulus of radius r_px and half-width half_px around (x, y) with color."""
        cx, cy = (x - self.x0) * self.scale, (self.y1 - y) * self.scale
        out = r_px + half_px
        c0, c1 = max(int(cx - out) - 1, 0), min(int(cx + out) + 2, self.W)
        r0, r1 = max(int(cy - out) - 1, 0), min(int(cy + out) + 2, self.H)
        if c0 >= c1 or r0 >= r1:
            return
        cc, rr = np.meshgrid(np.arange(c0, c1) + 0.5, np.arange(r0, r1) + 0.5)
        m = np.abs(np.hypot(cc - cx, rr - cy) - r_px) <= half_px
        patch = img[r0:r1, c0:c1]
        patch[m] = np.round(alpha * color + (1.0 - alpha) * patch[m]).astype(np.uint8)

    def _flashes(self, img, hud):
        """A ring at each recent impact point, widening and fading with the simulated time since it."""
        now = hud.get("time")
        impacts = hud.get("impacts") or ()
        if now is None or not impacts:
            return
        fade = FLASH_INTERVALS * self.core.scene.control_dt
        R = self.core.R
        for t, end, st in impacts:
            age = (now - t) / fade
            if not 0.0 <= age < 1.0:
                continue
            px, py = st[0] + end * R * math.cos(st[3]), st[1] + end * R * math.sin(st[3])
            self._ring(img, px, py, 4.0 + 8.0 * age, 1.6, FLASH, 1.0 - 0.8 * age)

    def _text(self, img, text):
        """The text line at the top left, white on a dark box, in the 3 x 5 font drawn TEXT_SCALE x."""
        k = TEXT_SCALE
        if self.H < 7 * k:
            return
        adv = 4 * k
        w = min(len(text) * adv + 2 * k, self.W)
        h = min(7 * k, self.H)
        img[:h, :w] = (0.3 * img[:h, :w] + 0.7 * TEXT_BOX).astype(np.uint8)
        for i, ch in enumerate(text):
            mask = _GLYPH_MASKS.get(ch)
            c0 = k + i * adv
            if mask is None or c0 + 3 * k > self.W:
                continue
            big = np.kron(mask, np.ones((k, k), bool))
            img[k:k + 5 * k, c0:c0 + 3 * k][big] = TEXT

    def frame(self, s, target, trail, arc, hud=None) -> np.ndarray:
        img = self._background_with_arc(arc).copy()
        for (px, py) in trail[:-1]:
            self._disc(img, px, py, 1.2, TRAIL)
        tolerance = getattr(self.core.task, "tolerance", None)  # (a task without a target radius: a dot)
        tol_px = tolerance * self.scale if tolerance is not None else 6.0
        self._disc(img, target[0], target[1], max(tol_px, 4.0), TARGET)
        x, y, _, ph, _, _ = s
        R = self.core.R
        c, sn = math.cos(ph), math.sin(ph)
        half = max(1.5, 0.12 * R * self.scale)
        self._segment(img, x - R * c, y - R * sn, x + R * c, y + R * sn, half, PENNY)
        self._disc(img, x + R * c, y + R * sn, max(2.5, 0.3 * R * self.scale), FRONT)
        if hud:
            self._flashes(img, hud)
            text = hud_text(hud)
            if text:
                self._text(img, text)
        return img

    def draw(self, s, target, trail, arc, hud=None):
        """The frame (rgb_array) or show it in the window (human); hud: see the module docstring."""
        img = self.frame(s, target, trail, arc, hud)
        if self.mode == "rgb_array":
            return img
        self._show(img)
        return None

    def _show(self, img):
        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
        try:
            import pygame
        except ImportError as exc:
            from gymnasium.error import DependencyNotInstalled
            raise DependencyNotInstalled('pygame-ce is needed for render_mode="human": the render extra '
                                          '(in a clone of penny_env: pip install -e ".[render]")') from exc
        if self.window is None:
            global _warned_no_display
            if not _has_display() and not _warned_no_display:
                _warned_no_display = True
                warnings.warn('render_mode="human": no display here (no DISPLAY / WAYLAND_DISPLAY, or SDL_VIDEODRIVER '
                              f'{os.environ.get("SDL_VIDEODRIVER", "")!r}), so no window will be visible; '
                              'use render_mode="rgb_array" to get the frames', UserWarning, stacklevel=4)
            pygame.display.init()  # the display only: pygame.init() would also open audio (ALSA noise)
            self.window = pygame.display.set_mode((self.W, self.H))
            pygame.display.set_caption("penny_env")
            self.clock = pygame.time.Clock()
        surf = pygame.surfarray.make_surface(np.ascontiguousarray(img.transpose(1, 0, 2)))
        self.window.blit(surf, (0, 0))
        pygame.event.pump()
        pygame.display.flip()
        self.clock.tick(self.fps)

    def close(self):
        if self.window is not None:
            import pygame
            pygame.display.quit()
            self.window = None
