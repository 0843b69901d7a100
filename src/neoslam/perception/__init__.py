"""Perception on real stereo images (paper 3.1): object detection, ORB stereo triangulation, stereo odometry.

Submodules import OpenCV and onnxruntime; import them directly (`neoslam.perception.detector`, ...), so that the
rest of NeoSLAM loads without them.
"""
