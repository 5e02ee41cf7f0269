"""``onionsort demo``: record, perceive, calibrate, learn and evaluate: the whole job.

Records 12 sessions of a person sorting onions while a passer-by blocks the camera, perceives
them with the shipped models, calibrates the observation model on fresh held-out frames, learns
the sorter's reward with MMAP-BIRL, MAP-BIRL and HiddenDataEM, lets the Sawyer sort 50 onions
with each learned policy (its inspection as ``onionsort evaluate``'s: ``--inspection-views``,
``--miss-cost``, ``--waste-cost``, ``--fusion``) and prints the paper's Table 1 beside ours.
``--quick`` runs it small. ``--methods`` picks other learners, e.g. behaviour cloning (``bc``,
``bc-em``) beside MMAP-BIRL. It ends by writing ``report.md`` in --out (``onionsort report``).
``--resume`` continues an interrupted demo in its --out from the last finished stage (same
results as an uninterrupted run); ``--connect URL`` streams the Rerun recordings to a viewer on
another machine as well.

Examples
--------
    onionsort demo
    onionsort demo --quick --out runs/demo-quick
    onionsort demo --quick --out runs/demo-quick --resume
    onionsort demo --connect rerun+http://192.168.1.20:9876/proxy
    onionsort demo --methods mmap-birl,map-birl,bc,bc-em --out runs/demo-bc   # + cloning
"""

from __future__ import annotations

from onionsort.commands import add_command
from onionsort.configs import config_from_args
from onionsort.configs.demo import DemoConfig


def register(subparsers) -> None:
    add_command(subparsers, "demo", __doc__,
                "record, perceive, calibrate, learn and evaluate: the whole job", DemoConfig, run)


def run(args) -> int:
    from onionsort.stages import demo
    from onionsort.stages.table1 import table

    results = demo(config_from_args(DemoConfig, args))
    print(f"effective noise: state error rate {results['state_error_rate']:.3f}, "
          f"(state, action) error rate {results['pair_error_rate']:.3f}")
    if results.get("sessions_read_backwards"):
        from onionsort.stages.calibrate import describe_session_swaps

        print(f"held-out sessions: {describe_session_swaps(results['sessions_read_backwards'])}")
    print(table(results))
    print(f"wrote {args.out / 'results.json'} ({results['seconds']:.0f} s)")
    print(f"report: {args.out / 'report.md'}")
    return 0
