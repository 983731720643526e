"""Synthetic reading sessions: printed pages, head and page motion, reading gaze and an event sensor.

Produces training shards (voxel grid, ideal ink mask) and full recordings in the recording format.
"""
