"""Drive NeoSLAM from another program, frame by frame (the Python API page's example, docs/api.md; tests run it)."""

import numpy as np

from neoslam import Frame, NeoSLAM, ObjectObservation, load_config
from neoslam.geometry import robot_points_to_camera

slam = NeoSLAM(load_config())  # the defaults; load_config(Path("my.yaml")) reads a file as --config does
parked_cars = np.array([[x, side * 4.0, -1.65] for x in range(10, 200, 7) for side in (-1, 1)])  # world, m
patch = np.full((16, 16), 128, dtype=np.uint8)  # a 16x16 grey appearance patch of each object

for index in range(150):
    pose = np.eye(4)  # T_world_robot from your odometry: x forward, y left, z up (REP-103)
    pose[0, 3] = 1.0 * index  # 1 m a frame, straight ahead
    offsets = parked_cars - pose[:3, 3]
    seen = offsets[(offsets[:, 0] > 3) & (offsets[:, 0] < 30)]  # what the camera sees, relative to the robot
    observations = tuple(
        ObjectObservation(
            label="car",
            score=0.9,
            box_left=np.zeros(4),  # pixel boxes: only for display
            box_right=np.zeros(4),
            center_camera=robot_points_to_camera(offset[None])[0],  # camera frame: x right, y down, z forward
            patch=patch,
        )
        for offset in seen
    )
    velocity = np.array([10.0, 0.0, 0.0]), np.zeros(3)  # body-frame linear (m/s) and angular (rad/s) velocity
    frame = Frame(index, 0.1 * index, pose, *velocity, observations=observations)  # index, timestamp (s), pose
    estimate = slam.step(frame)  # T_world_robot, corrected by the map

result = slam.result(frame_times_s=np.zeros(150))  # trajectories, objects, keyframes, closures, experience map
print(f"{len(result.keyframes)} keyframes, {len(result.objects)} objects, {len(result.loop_closures)} closures")
print("last corrected position (m):", result.estimate.poses[-1][:3, 3].round(2))
