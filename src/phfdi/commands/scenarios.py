"""phfdi scenarios: list the scenario, plant-model and fault presets."""

from __future__ import annotations

import argparse

from .common import EPILOG_FORMAT

EXAMPLES = """examples:
  phfdi scenarios
  phfdi scenarios --show paper      # the resolved scenario file
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("scenarios", help="list scenario, plant and fault presets",
                       description="List the built-in scenarios, plant models and the fault library.",
                       epilog=EXAMPLES, formatter_class=EPILOG_FORMAT)
    p.add_argument("--show", metavar="SCENARIO", help="print one scenario as resolved YAML")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import yaml

    from ph_plant_sim.build import PLANT_DIR
    from phfdi.faults import fault_library
    from phfdi.scenario import SCENARIO_DIR, load_scenario
    from phfdi_base.yamlfile import list_presets

    if args.show:
        spec = load_scenario(args.show)
        print(yaml.safe_dump(spec.model_dump(mode="json"), sort_keys=False), end="")
        return 0
    print("scenarios (--scenario NAME):")
    for name, desc in list_presets(SCENARIO_DIR).items():
        print(f"  {name:16s} {desc}")
    print("plant models (scenario key 'plant'):")
    for name, desc in list_presets(PLANT_DIR).items():
        print(f"  {name:16s} {desc}")
    print("faults (--fault NAME):")
    print(f"  {'healthy':16s} no fault")
    for name, f in fault_library().items():
        print(f"  {name:16s} {f.get('description', '')}")
    return 0
