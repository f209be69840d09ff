"""Recognition stage: rendered sign templates, kth-law MACE filter banks, FFT
correlation with PSR scoring, and the classifier that decides a sign's value.

No ROS imports here.
"""
