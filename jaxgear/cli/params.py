"""``jaxgear params``: print a preset's physical and dimensionless parameter tables."""

from __future__ import annotations

import json

from .._presets import resolve_params
from .common import add_param_options


def add_parser(sub) -> None:
    p = sub.add_parser(
        "params", help="print the physical and dimensionless parameter tables of a preset",
        description="Print the physical gear-set table (value, unit, source of each value) and the "
        "canonical dimensionless set (model document §4); --json prints only the dimensionless set.",
    )
    add_param_options(p)
    p.add_argument("--json", action="store_true", help="print the canonical dimensionless set as one JSON object")
    p.set_defaults(func=run)


def run(args) -> int:
    gear_set, params = resolve_params(args.preset, args.overrides)
    if args.json:
        print(json.dumps(params.to_dict()))
        return 0
    print(f"# preset: {args.preset} (physical units)")
    print(gear_set.table())
    print()
    print("# dimensionless parameters (model document §4)")
    print(params.table())
    return 0
