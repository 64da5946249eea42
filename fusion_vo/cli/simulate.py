"""``fusion-vo simulate OUT``: generate a recording over a photographed floor."""

from __future__ import annotations

import argparse
import importlib

from fusion_vo.errors import InputError
from fusion_vo.cli.arguments import positive_number, random_seed


class _LazyNames:
    """The sorted keys of ``module.attribute``, imported when argparse first looks at them.

    As ``choices`` (with a ``metavar``), it keeps the simulator, and with it numpy and OpenCV, out of
    ``fusion-vo --help`` and of every other command; ``simulate --help`` and a wrong name list them.
    """

    def __init__(self, module: str, attribute: str):
        self._where = (module, attribute)

    def _names(self) -> list[str]:
        return sorted(getattr(importlib.import_module(self._where[0]), self._where[1]))

    def __iter__(self):
        return iter(self._names())

    def __contains__(self, name) -> bool:
        return name in self._names()


def register(sub) -> None:
    p = sub.add_parser("simulate", help="generate a recording (camera, wheels, IMU, ground truth)",
                       description="Generate a recording in the layout of datasets/README.md: a differential-drive "
                                   "robot drives a profile over a floor made from a photographed texture. "
                                   "Options are the fields of fusion_vo.simulation.SimulationOptions "
                                   "(see datasets/generated.md).")
    p.add_argument("out", nargs="?", help="output folder: new, empty, or a recording fusion-vo wrote (then replaced)")
    p.add_argument("--force", action="store_true",
                   help="replace a non-empty folder that is not a recording fusion-vo wrote")
    p.add_argument("--profile", choices=_LazyNames("fusion_vo.simulation.robot", "PROFILES"), default=None,
                   metavar="PROFILE", help="driving profile, one of %(choices)s (default: square, or that of "
                                           "--standard or of the --config file)")
    p.add_argument("--standard", choices=_LazyNames("fusion_vo.simulation.standard", "STANDARD"), metavar="NAME",
                   help="one of the standard recordings, %(choices)s (fixes profile, options, seed)")
    p.add_argument("--seed", type=random_seed, default=None,
                   help="random seed (default: 0, or that of --standard or of the --config file)")
    p.add_argument("--duration", type=positive_number, help="duration [s] (random, standstill)")
    p.add_argument("--texture", choices=["gravel", "grass", "brick"])
    p.add_argument("--config", help="YAML file of options")
    p.add_argument("--option", "-O", action="append", default=[], metavar="KEY=VALUE",
                   help="set an option (YAML value), e.g. -O tilt_x_deg=2 -O highlight_radius=20")
    p.add_argument("--print-config", action="store_true",
                   help="print every option with its value (defaults, or those of --standard, --config and -O) "
                        "as YAML and exit")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import yaml

    from fusion_vo.config.files import load_yaml, load_yaml_text, validate
    from fusion_vo.config.render import commented_yaml, section_view
    from fusion_vo.simulation import SimulationOptions, simulate
    from fusion_vo.simulation.robot import SHAPE_OPTIONS
    from fusion_vo.simulation.standard import STANDARD

    from fusion_vo.simulation.robot import PROFILES

    if args.standard:
        profile, seed, options, _ = STANDARD[args.standard]
        options = dict(options)
    else:
        profile, seed, options = "square", 0, {}
    if args.config:  # its profile and seed (as --print-config writes them), then the options
        data = load_yaml(args.config)
        if "profile" in data:
            profile = data.pop("profile")
            if not isinstance(profile, str) or profile not in PROFILES:
                raise InputError(f"profile: expected one of {', '.join(PROFILES)}, got {profile!r}", args.config)
        if "seed" in data:
            seed = data.pop("seed")
            if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
                raise InputError(f"seed: expected a whole number of at least 0, got {seed!r}", args.config)
        options.update(data)
    profile = profile if args.profile is None else args.profile
    seed = seed if args.seed is None else args.seed
    for item in args.option:
        key, _, value = item.partition("=")
        if "=" not in item or not key.strip():
            raise InputError(f"--option needs KEY=VALUE, got '{item}'")
        try:
            options[key.strip()] = load_yaml_text(value)
        except yaml.YAMLError as exc:
            shown = value if len(value) <= 40 else value[:37] + "..."
            raise InputError(f"--option {key}: '{shown}' is not a valid value ({getattr(exc, 'problem', None) or 'YAML'})"
                             ) from None
    if args.duration is not None:
        options["duration"] = args.duration
    if args.texture:
        options["texture"] = args.texture
    opts = validate(SimulationOptions, options, args.config)
    # a shape option given on the command line that the profile ignores would be silently lost (a --config
    # file may hold them all: --print-config writes every option, and its output is meant to be read back)
    for key, profiles in SHAPE_OPTIONS.items():
        if getattr(opts, key) is not None and profile not in profiles:
            given = "--duration" if key == "duration" and args.duration is not None else (
                f"-O {key}" if any(o.split("=", 1)[0].strip() == key for o in args.option) else None)
            if given:
                raise InputError(f"{given}: not used by the '{profile}' profile (only by {', '.join(profiles)})")
    if args.print_config:
        header = ["# fusion-vo simulate options: --config reads them back", f"profile: {profile}  # driving profile",
                  f"seed: {seed}  # random seed"]
        print("\n".join(header + commented_yaml(section_view(SimulationOptions), opts.model_dump(mode="json"))))
        return 0
    if not args.out:
        raise InputError("simulate needs an output folder (see fusion-vo simulate --help)")
    try:
        out = simulate(args.out, profile=profile, seed=seed, options=opts, force=args.force)
    except ValueError as exc:  # a combination of options the profile cannot drive
        raise InputError(str(exc), args.config) from None
    except OSError as exc:
        raise InputError(f"cannot write the recording ({exc.strerror or exc})", args.out) from None
    info = load_yaml(out / "simulation.yaml")["summary"]
    print(f"{info['frames']} frames, {info['duration_s']:.1f} s, {info['path_length_m']:.2f} m path -> {out}")
    return 0
