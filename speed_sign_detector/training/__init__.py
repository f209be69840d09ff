"""Bank building: what only ``speed_sign_train`` uses, never the node.

Labelled crops and annotated scenes turned into training examples (with degraded copies),
the trained filters and the second opinion fitted on them, and validation that keeps
physical signs apart (k folds by track or by scene). It imports
:mod:`speed_sign_detector.recognition` (the reader it trains for), never the other way.

No ROS imports here.
"""
