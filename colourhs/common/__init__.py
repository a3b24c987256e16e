"""What every stage shares.

Geometry (:mod:`.geometry`), image sampling (:mod:`.sampling`), ray casting a
mesh into a camera (:mod:`.raycast`, :mod:`.closest_point`), PLY meshes
(:mod:`.ply`), the depth file (:mod:`.depthfile`), the metrics table
(:mod:`.metrics_csv`), sparse solves (:mod:`.linalg`), colour maps
(:mod:`.colours`), whole-or-nothing outputs (:mod:`.files`), progress
(:mod:`.progress`) and open3d's start-up (:mod:`.lazy_open3d`). It imports
no stage; of the rest of the package only :mod:`colourhs.capture` (the rig's
types).
"""
