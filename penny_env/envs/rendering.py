"""Frames of the penny: a small numpy rasterizer ("rgb_array") and a pygame-ce window ("human").

The frame shows the table (inside light, outside dark, the wall as a line, the marked arc of
the impacts task in orange), the target (blue disc), the trail of the contact point (grey dots)
and the penny seen from above: a black segment between its two ends with its front end marked
by a red disc. y points up. pygame is imported only by the "human" mode.
"""
from __future__ import annotations

import math

import numpy as np

INSIDE = np.array([236, 242, 228], np.uint8)
OUTSIDE = np.array([70, 74, 82], np.uint8)
PLANE = np.array([245, 245, 245], np.uint8)
GRID = np.array([225, 225, 225], np.uint8)
WALL = np.array([30, 30, 30], np.uint8)
ARC = np.array([255, 150, 0], np.uint8)
TARGET = np.array([40, 90, 230], np.uint8)
TRAIL = np.array([150, 150, 170], np.uint8)
PENNY = np.array([0, 0, 0], np.uint8)
FRONT = np.array([220, 30, 30], np.uint8)


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
        if self.core.plane or not self.core.impacts or self.core.k.all_arc:
            return self._background
        if self._arc_for != arc:
            img = self._background.copy()
            X, Y = self._grid()
            h = self.core.table.h(X, Y)
            gx, gy = self.core.table.grad(X, Y)
            dist = np.abs(h) / np.maximum(np.hypot(gx, gy), 1e-12)
            cb, sb = arc
            on = X * cb + Y * sb >= self.core.k.cos_hw * np.hypot(X, Y)
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

    def frame(self, s, target, trail, arc) -> np.ndarray:
        img = self._background_with_arc(arc).copy()
        for (px, py) in trail[:-1]:
            self._disc(img, px, py, 1.2, TRAIL)
        tol_px = self.core.k.tol * self.scale if not self.core.impacts else 6.0
        self._disc(img, target[0], target[1], max(tol_px, 4.0), TARGET)
        x, y, _, ph, _, _ = s
        R = self.core.R
        c, sn = math.cos(ph), math.sin(ph)
        half = max(1.5, 0.12 * R * self.scale)
        self._segment(img, x - R * c, y - R * sn, x + R * c, y + R * sn, half, PENNY)
        self._disc(img, x + R * c, y + R * sn, max(2.5, 0.3 * R * self.scale), FRONT)
        return img

    def draw(self, s, target, trail, arc):
        img = self.frame(s, target, trail, arc)
        if self.mode == "rgb_array":
            return img
        self._show(img)
        return None

    def _show(self, img):
        try:
            import pygame
        except ImportError as exc:
            from gymnasium.error import DependencyNotInstalled
            raise DependencyNotInstalled('pygame-ce is needed for render_mode="human": pip install "penny-env[render]"') from exc
        if self.window is None:
            pygame.init()
            pygame.display.init()
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
            pygame.quit()
            self.window = None
