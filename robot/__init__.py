"""The PyBullet onion-sorting world: scene, onions, human sorter, passer-by, cameras, Sawyer.

Importing this package is cheap: pybullet is imported by the submodules that need it
(:mod:`robot.scene`, :mod:`robot.camera`, :mod:`robot.sawyer`, :mod:`robot.simulation`).
The mapping between the physical world and the MDP state lives in :mod:`robot.state_map`;
the ground-truth label types shared with ``recordings/`` live in :mod:`robot.labels`.
"""
