"""RGB-D camera in front of the cabinet and the recoloured top-down heightmap (§IV-A).

Pipeline: render depth + segmentation -> point cloud (precomputed per-pixel rays) -> keep the
points inside the cabinet -> per heightmap cell, the highest point and the body it belongs to.
Cells that no point landed in are decided by projecting them back into the depth image: if the
camera sees the highest neighbouring surface there, the cell takes that surface (fills sampling
holes on object tops); else if it sees the floor there, the cell is free; otherwise something
nearer hides it and the cell is occluded. Object masks therefore cover visible parts only — no
amodal completion, and a fully hidden object does not appear at all.

The *semantic map* (per cell: object uid, FREE or OCCLUDED, and height) is kept apart from the
colours so that hindsight relabelling can recolour the same view with other classes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pybullet as pb

from shelf_env import params
from shelf_env.actions import cell_centres, occupancy_masks

FREE = -1
OCCLUDED = -2

CLASS_RGB = np.array([[0, 200, 0], [255, 220, 0], [0, 60, 255]], dtype=np.uint8)
REGION_RGB = np.array([[190, 250, 190], [255, 245, 180], [190, 205, 255]], dtype=np.uint8)
FREE_RGB = np.array([255, 255, 255], dtype=np.uint8)
OCCLUDED_RGB = np.array([128, 128, 128], dtype=np.uint8)
HEIGHT_QUANTUM = 0.0005  # metres per step of the internal height key


@dataclass(frozen=True)
class CameraConfig:
    """Pinhole camera looking into the cabinet. The field of view is computed so that the
    whole opening and the back floor are in the image."""

    position: tuple[float, float, float] = (-0.50, 0.0, 0.40)
    target: tuple[float, float, float] = (0.22, 0.0, 0.02)
    width: int = 640
    height: int = 480
    near: float = 0.05
    far: float = 3.0
    depth_tolerance: float = 0.01  # metres: "sees this point" when depths agree this well


def _look_at(cfg: CameraConfig) -> np.ndarray:
    """Rotation whose rows are the camera's right, up and forward axes in the world."""
    pos, tgt = np.array(cfg.position), np.array(cfg.target)
    fwd = (tgt - pos) / np.linalg.norm(tgt - pos)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    return np.stack([right, up, fwd])


class HeightmapCamera:
    """Captures the cabinet and turns it into a semantic heightmap."""

    def __init__(self, client: int, cfg: CameraConfig | None = None, pixel_size: float = params.PIXEL_SIZE,
                 hidden_bodies: tuple[tuple[int, tuple], ...] = (), wall_uids: tuple[int, ...] = ()):
        self.client = client
        # points on the cabinet's walls and ceiling are not part of the floor plan
        self.wall_uids = np.asarray(wall_uids, dtype=np.int64)
        # decorative bodies (body uid, rgba) that cannot be seen through the opening but cost
        # TinyRenderer fill time: made transparent while this camera captures
        self.hidden_bodies = hidden_bodies
        self.cfg = cfg = cfg or CameraConfig()
        self.pixel_size = pixel_size
        self.rows = int(round(params.CABINET_DEPTH / pixel_size))
        self.cols = int(round(params.CABINET_WIDTH / pixel_size))
        self.rot = _look_at(cfg)
        self.pos = np.array(cfg.position)
        aspect = cfg.width / cfg.height
        # field of view covering the opening and the back floor, with a 3 % margin
        d, w, h = params.CABINET_DEPTH, params.CABINET_WIDTH, params.CABINET_HEIGHT
        corners = np.array([[x, y, z] for x in (0.0, d) for y in (-w / 2, w / 2) for z in (0.0, h)])
        cam = (corners - self.pos) @ self.rot.T
        tan_x = np.abs(cam[:, 0] / cam[:, 2]).max()
        tan_y = np.abs(cam[:, 1] / cam[:, 2]).max()
        self.tan_half_v = max(tan_y, tan_x / aspect) * 1.03
        self.tan_half_h = self.tan_half_v * aspect
        fov = float(np.degrees(2 * np.arctan(self.tan_half_v)))
        self.view = pb.computeViewMatrix(cfg.position, cfg.target, [0, 0, 1], physicsClientId=client)
        self.proj = pb.computeProjectionMatrixFOV(fov, aspect, cfg.near, cfg.far, physicsClientId=client)
        # per-pixel ray (world frame) scaled to unit forward component: point = pos + depth * ray
        u = (np.arange(cfg.width) + 0.5) / cfg.width * 2 - 1
        v = 1 - (np.arange(cfg.height) + 0.5) / cfg.height * 2
        uu, vv = np.meshgrid(u * self.tan_half_h, v * self.tan_half_v)
        rays_cam = np.stack([uu, vv, np.ones_like(uu)], axis=-1)
        rays = rays_cam @ self.rot
        # only pixels that look through the opening can see the interior
        t = -self.pos[0] / rays[..., 0]
        hit_y = self.pos[1] + t * rays[..., 1]
        hit_z = self.pos[2] + t * rays[..., 2]
        through = (t > 0) & (np.abs(hit_y) <= w / 2 + 0.01) & (hit_z >= -0.01) & (hit_z <= h + 0.01)
        self._pix = np.flatnonzero(through.ravel())
        self._rays = rays.reshape(-1, 3)[self._pix]
        # cell centres (rows: back -> front, cols: camera's left -> right)
        self.cell_x, self.cell_y = cell_centres(self.rows, self.cols, pixel_size)
        cx, cy = np.meshgrid(self.cell_x, self.cell_y, indexing="ij")
        self._cell_xy = np.stack([cx.ravel(), cy.ravel()], axis=1)
        self._floor_uv, self._floor_depth = self.project(np.c_[self._cell_xy, np.zeros(len(self._cell_xy))])

    # ---- geometry --------------------------------------------------------------------
    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Image pixel (flat index, -1 if outside) and forward depth of world points (K, 3)."""
        cam = (points - self.pos) @ self.rot.T
        z = cam[:, 2]
        u = ((cam[:, 0] / z / self.tan_half_h) + 1) / 2 * self.cfg.width
        v = (1 - cam[:, 1] / z / self.tan_half_v) / 2 * self.cfg.height
        ui, vi = np.floor(u).astype(int), np.floor(v).astype(int)
        ok = (z > 0) & (ui >= 0) & (ui < self.cfg.width) & (vi >= 0) & (vi < self.cfg.height)
        return np.where(ok, vi * self.cfg.width + ui, -1), z

    # ---- capture ---------------------------------------------------------------------
    def render(self) -> tuple[np.ndarray, np.ndarray]:
        """Forward depth in metres (H*W,) and segmentation body uids (H*W,)."""
        cfg = self.cfg
        for uid, _ in self.hidden_bodies:
            pb.changeVisualShape(uid, -1, rgbaColor=(0, 0, 0, 0), physicsClientId=self.client)
        _, _, _, zbuf, seg = pb.getCameraImage(
            cfg.width, cfg.height, self.view, self.proj, renderer=pb.ER_TINY_RENDERER,
            physicsClientId=self.client,
        )
        for uid, rgba in self.hidden_bodies:
            pb.changeVisualShape(uid, -1, rgbaColor=rgba, physicsClientId=self.client)
        zbuf = np.asarray(zbuf, dtype=np.float64).reshape(-1)
        depth = cfg.far * cfg.near / (cfg.far - (cfg.far - cfg.near) * zbuf)
        return depth, np.asarray(seg, dtype=np.int64).reshape(-1)

    def front_edges(self, object_uids: np.ndarray | list[int]) -> dict[int, float]:
        """Capture and return, per object of ``object_uids`` that the camera sees inside the cabinet,
        the smallest x of its visible points: how close to the opening its front is (metres).

        A cheap check for the closed loop (`shelf_env.conditions.closed_loop.DragWatch`): with a small image it
        costs ~3 ms, and occlusion can only hide points, so an edge that comes closer to the
        opening than before means the object moved towards it."""
        depth_img, seg_img = self.render()
        depth = depth_img[self._pix]
        pts = self.pos + depth[:, None] * self._rays
        seg = seg_img[self._pix]
        d, w = params.CABINET_DEPTH, params.CABINET_WIDTH
        keep = (pts[:, 0] >= 0) & (pts[:, 0] < d) & (np.abs(pts[:, 1]) < w / 2) & np.isin(seg, object_uids)
        pts, seg = pts[keep], seg[keep]
        order = np.argsort(seg, kind="stable")
        uids, starts = np.unique(seg[order], return_index=True)
        return {int(u): float(v) for u, v in zip(uids, np.minimum.reduceat(pts[order, 0], starts))} if len(uids) else {}

    def semantic_map(self, object_uids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Capture and return (cell_uid (H, W) int, cell_height (H, W) float metres).

        ``cell_uid`` is an object uid, FREE or OCCLUDED. Bodies that are not objects (cabinet,
        robot) count as free space where seen at floor level.
        """
        depth_img, seg_img = self.render()
        depth = depth_img[self._pix]
        pts = self.pos + depth[:, None] * self._rays
        seg = seg_img[self._pix]
        d, w, h = params.CABINET_DEPTH, params.CABINET_WIDTH, params.CABINET_HEIGHT
        keep = ((pts[:, 0] >= 0) & (pts[:, 0] < d) & (np.abs(pts[:, 1]) < w / 2) & (pts[:, 2] > -0.005)
                & (pts[:, 2] < h - 0.002) & ~np.isin(seg, self.wall_uids))
        pts, seg = pts[keep], seg[keep]
        # object index code: 0 = not an object, i + 1 = object_uids[i]
        lookup = np.zeros(max(int(seg.max(initial=0)), int(object_uids.max(initial=0))) + 2, dtype=np.int64)
        lookup[object_uids + 1] = np.arange(1, len(object_uids) + 1)
        code = np.where(seg >= 0, lookup[np.clip(seg, -1, None) + 1], 0)
        n_code = len(object_uids) + 1
        row = ((d - pts[:, 0]) / self.pixel_size).astype(int)
        col = ((w / 2 - pts[:, 1]) / self.pixel_size).astype(int)
        cell = np.clip(row, 0, self.rows - 1) * self.cols + np.clip(col, 0, self.cols - 1)
        hq = np.clip(np.round(pts[:, 2] / HEIGHT_QUANTUM), 0, None).astype(np.int64)
        key = np.full(self.rows * self.cols, -1, dtype=np.int64)
        np.maximum.at(key, cell, hq * n_code + code)
        # fill sampling holes: a cell with observed cells on both sides (above/below or
        # left/right) takes their highest surface, if the camera sees that surface there
        empty = np.flatnonzero(key < 0)
        if len(empty):
            kp = np.pad(key.reshape(self.rows, self.cols), 1, constant_values=-1)
            up, down, left, right = kp[:-2, 1:-1], kp[2:, 1:-1], kp[1:-1, :-2], kp[1:-1, 2:]
            vert = np.where((up >= 0) & (down >= 0), np.maximum(up, down), -1)
            horiz = np.where((left >= 0) & (right >= 0), np.maximum(left, right), -1)
            neigh = np.maximum(vert, horiz).reshape(-1)
            cand = empty[neigh[empty] >= 0]
            if len(cand):
                z = (neigh[cand] // n_code) * HEIGHT_QUANTUM
                pix, zc = self.project(np.c_[self._cell_xy[cand], z])
                seen = (pix >= 0) & (np.abs(depth_img[np.maximum(pix, 0)] - zc) < self.cfg.depth_tolerance)
                key[cand[seen]] = neigh[cand[seen]]
            empty = np.flatnonzero(key < 0)
        cell_uid = np.full(self.rows * self.cols, FREE, dtype=np.int64)
        height = np.zeros(self.rows * self.cols)
        obs = key >= 0
        code_obs = key[obs] % n_code
        height[obs] = (key[obs] // n_code) * HEIGHT_QUANTUM
        cell_uid[np.flatnonzero(obs)[code_obs > 0]] = object_uids[code_obs[code_obs > 0] - 1]
        if len(empty):
            pix = self._floor_uv[empty]
            hidden = (pix < 0) | (depth_img[np.maximum(pix, 0)] < self._floor_depth[empty] - self.cfg.depth_tolerance)
            cell_uid[empty[hidden]] = OCCLUDED
        return cell_uid.reshape(self.rows, self.cols), height.reshape(self.rows, self.cols)


def region_masks(regions, rows: int, cols: int, pixel_size: float) -> np.ndarray:
    """Boolean (K, H, W): which cells' centres lie in each target region."""
    x, y = cell_centres(rows, cols, pixel_size)
    out = np.zeros((len(regions), rows, cols), dtype=bool)
    for k, r in enumerate(regions):
        out[k] = ((x >= r.x0) & (x <= r.x1))[:, None] & ((y >= r.y0) & (y <= r.y1))[None, :]
    return out


def observed_height(obs: np.ndarray) -> np.ndarray:
    """(H, W) metres from an observation's height channel: the inverse of `recolour`'s encoding
    (to its 8-bit step, ~1 mm)."""
    return np.asarray(obs)[3].astype(float) / 255.0 * params.CABINET_HEIGHT


def recolour(cell_uid: np.ndarray, height: np.ndarray, class_of_uid: dict[int, int],
             regions: np.ndarray) -> np.ndarray:
    """The observation (4, H, W) uint8: class colours, white free space, region tints, grey
    occlusion, and height over the cabinet height in 0..255."""
    rgb = np.empty(cell_uid.shape + (3,), dtype=np.uint8)
    rgb[:] = FREE_RGB
    free = cell_uid == FREE
    for k in range(len(regions)):
        rgb[free & regions[k]] = REGION_RGB[k]
    rgb[cell_uid == OCCLUDED] = OCCLUDED_RGB
    for uid, cls in class_of_uid.items():
        rgb[cell_uid == uid] = CLASS_RGB[cls]
    h8 = np.clip(np.round(height / params.CABINET_HEIGHT * 255), 0, 255).astype(np.uint8)
    return np.concatenate([rgb.transpose(2, 0, 1), h8[None]], axis=0)


def observation_masks(obs: np.ndarray, pixel_size: float, names: Sequence[str]) -> np.ndarray:
    """`shelf_env.actions.occupancy_masks` read from an observation ``(4, H, W)`` alone: its object
    cells are those in a class colour. Equal to the env's ``action_masks()`` without ``safe_picks`` (a
    test checks it), so stored observations (the teacher dataset's) get their masks back without the simulator."""
    rgb = np.moveaxis(np.asarray(obs)[:3], 0, -1)
    occupied = (rgb[:, :, None, :] == CLASS_RGB[None, None]).all(axis=-1).any(axis=-1)
    return occupancy_masks(occupied, pixel_size, names)
