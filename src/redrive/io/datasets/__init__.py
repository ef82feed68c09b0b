"""Dataset folders read as logs: KITTI 3D object, nuScenes tables, mmdetection3d nuScenes infos."""
