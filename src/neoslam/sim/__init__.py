"""Simulation of what a robot with a stereo camera and an object detector records along a trajectory."""
