"""Detection stage: 3x3 Sobel gradients and radial-symmetry voting (GL or numpy).

No ROS imports here.
"""
