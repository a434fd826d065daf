"""The camera and the observation (§IV-A): RGB-D capture from the front, the top-down heightmap,
recolouring by class, occlusion (`heightmap`)."""

from shelf_env.camera.heightmap import CLASS_RGB, CameraConfig, HeightmapCamera, recolour, region_masks

__all__ = ["CLASS_RGB", "CameraConfig", "HeightmapCamera", "recolour", "region_masks"]
