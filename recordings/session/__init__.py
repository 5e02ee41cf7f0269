"""The session: one MCAP file per recorded session, its format and the code that reads and
writes it.

- :mod:`~recordings.session.schema`: topics, message schemas and metadata records (sensor side,
  ground truth, perception, a robot's run);
- :mod:`~recordings.session.writer` and :mod:`~recordings.session.reader`: frame by frame to
  MCAP, and back, with recovery of a damaged file;
- :mod:`~recordings.session.rewrite`: atomic rewrites (stripping ground truth), and
  :mod:`~recordings.session.perception` adding the perception topics through one;
- :mod:`~recordings.session.frames`: what the writers read of a simulator's frames (protocols);
  :mod:`~recordings.session.steps`: grouping frames into steps;
- :mod:`~recordings.session.world` and :mod:`~recordings.session.urdf`: the 3D side
  (transforms, joint states, scene) and a robot's kinematics from its URDF.
"""
