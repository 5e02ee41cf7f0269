"""The PyBullet onion-sorting world: scene, onions, human sorter, passer-by, cameras, Sawyer.

Importing this package is cheap: pybullet is imported by the submodules that need it
(:mod:`robot.scene`, :mod:`robot.camera`, :mod:`robot.sawyer`, :mod:`robot.simulation`).
The mapping between the physical world and the MDP state lives in :mod:`robot.state_map`;
the ground-truth label types shared with ``recordings/`` live in :mod:`robot.labels`.

Importing it also registers the Gymnasium environment :data:`SORTING_ENV_ID`
(:class:`robot.gym_env.SortingEnv`, built only when ``gymnasium.make`` asks for it).
"""

import gymnasium

SORTING_ENV_ID = "onionsort/Sorting-v0"
"""The sorting station's Gymnasium id: ``gymnasium.make(SORTING_ENV_ID, n_onions=..., ...)``."""

if SORTING_ENV_ID not in gymnasium.registry:
    gymnasium.register(id=SORTING_ENV_ID, entry_point="robot.gym_env:SortingEnv")
