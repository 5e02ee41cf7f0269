"""The ``irl`` library on an MDP of your own: the script of the tutorial docs/irl.md.

A person drives a courier robot by remote from a door to a drop-off and back. The short way is
through the door, which is mostly closed; the long way goes around by the hall. We log where
the robot was and what it was told to do; a camera reads whether the door was open, and it
often sees the closed (glass) door as open; some steps were not logged at all. From that log
we learn what the person wants (the reward) with MMAP-BIRL, which knows how the camera errs,
and with MAP-BIRL, which takes every reading at face value, and compare them with the
person's own policy.

Run it as ``python examples/irl_tutorial.py`` (one log, seed 1, and the posterior) or
``python examples/irl_tutorial.py --seeds 40`` (how often each learner finds the person's
policy over 40 logs). tests/test_examples.py runs it and checks what docs/irl.md says.
"""

from __future__ import annotations

import argparse

import numpy as np

import irl
from irl.demonstrations import sample_trajectory
from irl.solvers import OptimalQSolver, boltzmann_policy

# -- 1. The MDP: T[s, a, s'] and phi[s, a, k] --------------------------------------------------

POSITIONS = ("door", "doorway", "drop-off", "hall 1", "hall 2")
DOOR = ("closed", "open")
ACTIONS = ("wait", "through", "around")
FEATURES = ("delivered", "moving", "in doorway")
#: A state is (position, door): s = position * 2 + door, as np.ravel_multi_index orders them.
SIZES = (len(POSITIONS), len(DOOR))
STATES = [f"{p}, door {d}" for p in POSITIONS for d in DOOR]
S, A, K = len(STATES), len(ACTIONS), len(FEATURES)
#: P(door next | door now): a closed door opens 1 step in 10; an open one closes half the time.
DOOR_CHANGES = np.array([[0.9, 0.1],
                         [0.5, 0.5]])


def next_position(position: str, door: str, action: str) -> str:
    """Where the robot is after ``action``: through the door only when it is open, around by
    the hall in three steps, back to the door after each delivery; waiting stays put."""
    if position == "drop-off":
        return "door"  # the next parcel
    if action == "wait":
        return position
    if position == "door":
        if action == "around":
            return "hall 1"
        return "doorway" if door == "open" else "door"  # a closed door stops the robot
    return {"doorway": "drop-off", "hall 1": "hall 2", "hall 2": "drop-off"}[position]


def build_mdp() -> irl.TabularMDP:
    """The courier's MDP, its arrays written out from the rules above."""
    T = np.zeros((S, A, S))
    phi = np.zeros((S, A, K))
    for s in range(S):
        p, d = np.unravel_index(s, SIZES)
        for a, action in enumerate(ACTIONS):
            q = POSITIONS.index(next_position(POSITIONS[p], DOOR[d], action))
            for d2 in range(len(DOOR)):  # the door changes on its own
                T[s, a, np.ravel_multi_index((q, d2), SIZES)] += DOOR_CHANGES[d, d2]
            phi[s, a] = [POSITIONS[p] == "drop-off", action != "wait",
                         POSITIONS[p] == "doorway"]
    start = np.zeros(S)
    start[[STATES.index("door, door closed"), STATES.index("door, door open")]] = [0.8, 0.2]
    return irl.TabularMDP(transitions=T, features=phi, discount=0.9, initial=start,
                          state_names=STATES, action_names=ACTIONS, feature_names=FEATURES)


# -- 2. The person, and the log we get of them -----------------------------------------------

#: What the person wants: deliveries, a little less driving; the doorway does not matter.
TRUE_THETA = np.array([1.0, -0.1, 0.0])
#: How consistently they act on it: pi(a | s) = softmax_a(BETA * Q*(s, a)).
BETA = 5.0
#: The camera's true errors, P(reading | door): a closed door is read open 4 times in 10.
CAMERA = np.array([[0.6, 0.4],
                   [0.05, 0.95]])
#: Share of steps missing from the log.
GAPS = 0.2


def simulate_log(mdp: irl.TabularMDP, n_runs: int = 30, length: int = 20, seed: int = 0
                 ) -> list[list[tuple[str, str, str] | None]]:
    """Stands in for your robot's log: per run, one row ``(position, door reading, action)``
    a step, or ``None`` for a step that was not logged."""
    rng = np.random.default_rng(seed)
    expert = boltzmann_policy(OptimalQSolver(mdp).q_values(TRUE_THETA), BETA)
    log = []
    for _ in range(n_runs):
        truth = sample_trajectory(mdp, expert, length, rng)
        rows = []
        for s, a in zip(truth.states, truth.actions, strict=True):
            p, d = np.unravel_index(s, SIZES)
            read = rng.choice(len(DOOR), p=CAMERA[d])
            rows.append(None if rng.random() < GAPS else (POSITIONS[p], DOOR[read], ACTIONS[a]))
        log.append(rows)
    return log


# -- 3. The observation model, from a measured confusion matrix ------------------------------

#: What we measured: the camera's readings of 100 frames of a closed door and 100 of an open
#: one, labelled by hand. MEASURED[true door, reading].
MEASURED = np.array([[62, 38],
                     [4, 96]])


def observation_model() -> irl.FactoredObservationModel:
    """P(o | s, a) for o = s' * A + a': the position and the action are read exactly, the
    door through the measured confusion (add-one smoothed, rows normalized)."""
    door = (MEASURED + 1) / (MEASURED + 1).sum(axis=1, keepdims=True)
    position = np.eye(len(POSITIONS))
    return irl.factored_observation_model([position, door], n_actions=A)


# -- 4. Logged rows -> demonstrations --------------------------------------------------------

def to_demonstration(rows: list[tuple[str, str, str] | None]) -> irl.Demonstration:
    """One run of the log as observation indices: the state read, s' = position * 2 + door,
    and the action a' make o = s' * A + a'; a missing step is None (occluded)."""
    observations = []
    for row in rows:
        if row is None:
            observations.append(None)
            continue
        position, door, action = row
        s = int(np.ravel_multi_index((POSITIONS.index(position), DOOR.index(door)), SIZES))
        observations.append(s * A + ACTIONS.index(action))
    return irl.Demonstration(observations=observations)


# -- 5. Fit MMAP-BIRL and the face-value baseline, and compare -------------------------------

def fit_both(mdp, sensor, demos, beta: float = BETA) -> dict[str, irl.MMAPBIRL | irl.MAPBIRL]:
    """MMAP-BIRL marginalizes each step over what it may have been; MAP-BIRL reads each
    logged step as the pair it reports. Same MDP, observation model, beta and prior."""
    prior = irl.GaussianPrior(mean=0.0, std=1.0)
    return {name: cls(mdp, sensor, beta=beta, prior=prior, seed=0).fit(demos)
            for name, cls in (("MMAP-BIRL", irl.MMAPBIRL), ("MAP-BIRL", irl.MAPBIRL))}


def compare(mdp, fitted) -> None:
    """Each learner's weights, the share of the person's value its policy loses (normalized
    ILE), and what it does at the door."""
    expert = OptimalQSolver(mdp).solve(TRUE_THETA).policy
    closed, open_ = STATES.index("door, door closed"), STATES.index("door, door open")
    print("           theta: delivered, moving, in doorway   value lost   door closed  door open")
    print(f"{'person':9}  {np.array2string(TRUE_THETA, precision=2):35}  {'':10}   "
          f"{ACTIONS[expert[closed]]:11}  {ACTIONS[expert[open_]]}")
    for name, est in fitted.items():
        lost = irl.normalized_inverse_learning_error(mdp, TRUE_THETA, est.theta_)  # percent
        print(f"{name:9}  {np.array2string(est.theta_, precision=2):35}  {lost:9.1f}%   "
              f"{ACTIONS[est.policy_[closed]]:11}  {ACTIONS[est.policy_[open_]]}")


def recovered(mdp, fitted) -> dict[str, bool]:
    """Whether each learner's greedy policy is the person's in every state."""
    return {name: irl.policy_mismatch(mdp, TRUE_THETA, est.theta_) == 0.0
            for name, est in fitted.items()}


# -- 6. Read the posterior -------------------------------------------------------------------

def read_posterior(fitted, demos, method: str = "laplace") -> None:
    """How sure each learner is: its weights' posterior and its confidence in going through
    the open door."""
    from irl.posterior import sample_posterior

    open_door = STATES.index("door, door open")
    for name, est in fitted.items():
        post = sample_posterior(est, demos, n_samples=400, method=method, seed=0)
        mean, sd = post.theta.mean(axis=0), post.theta.std(axis=0)
        sure = post.action_confidence()[open_door, ACTIONS.index("through")]
        print(f"{name}: theta {np.array2string(mean, precision=2)} +- "
              f"{np.array2string(sd, precision=2)}; P(through | door open) {sure:.2f}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=1, help="the log's seed (default: 1)")
    parser.add_argument("--seeds", type=int, default=0,
                        help="count, over logs of seeds 0..N-1, how often each learner finds "
                             "the person's policy (default: 0, off)")
    parser.add_argument("--beta", type=float, default=BETA,
                        help="the beta the learners assume (default: the person's, 5)")
    parser.add_argument("--posterior", choices=("laplace", "mcmc"), default="laplace",
                        help="how the posterior is drawn (default: laplace)")
    args = parser.parse_args(argv)
    mdp, sensor = build_mdp(), observation_model()
    if args.seeds:
        wins = {"MMAP-BIRL": 0, "MAP-BIRL": 0}
        for seed in range(args.seeds):
            demos = [to_demonstration(run) for run in simulate_log(mdp, seed=seed)]
            for name, ok in recovered(mdp, fit_both(mdp, sensor, demos, args.beta)).items():
                wins[name] += ok
        for name, n in wins.items():
            print(f"{name}: the person's policy on {n} of {args.seeds} logs")
        return 0
    log = simulate_log(mdp, seed=args.seed)
    demos = [to_demonstration(run) for run in log]
    print(f"{len(demos)} runs, {sum(d.n_occluded for d in demos)} of "
          f"{sum(len(d) for d in demos)} steps missing; the first: {log[0][:3]}")
    fitted = fit_both(mdp, sensor, demos, args.beta)
    compare(mdp, fitted)
    read_posterior(fitted, demos, args.posterior)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
