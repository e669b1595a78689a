"""`aerobase` command line: dispatches to the server, the daemons, the simulator and the demo.

Each deployable owns its own argument parsing (`main(argv)`); this module only routes the
first word(s) of the command line, importing the chosen part lazily so that starting a
daemon never imports the server and vice versa.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence

USAGE = """usage: aerobase COMMAND ...

commands:
  server                    serve the backend (applies migrations on start)
  admin ...                 migrate, create-org, create-user, create-superuser, token
  asset decrypt FILE        print a decrypted asset configuration file
  base-station --config F   run the landing-base daemon
  agent --config F          run the companion-computer daemon
  sim world                 serve the simulated world (--follow URL: around an external autopilot)
  sim autopilot             serve the simulated autopilot alone, on two MAVLink TCP ports
  sim precland-eval         evaluate precision landing in the simulated world (bench/precland_eval.py)
  demo                      everything on embedded defaults, one autonomous mission
"""

# command words -> "module:function" taking the remaining argv
ROUTES: dict[tuple[str, ...], str] = {
    ("server",): "server.cli:server_main",
    ("admin",): "server.cli:admin_main",
    ("asset",): "assetlink.configfile_cli:main",
    ("base-station",): "base_station.main:main",
    ("agent",): "asset_agent.main:main",
    ("sim", "world"): "sim.assemble:main",
    ("sim", "autopilot"): "sim.autopilot:main",
    ("sim", "precland-eval"): "bench.precland_eval:main",
    ("demo",): "aerobase.demo.run:main",
}


def resolve(argv: Sequence[str]) -> tuple[str, list[str]] | None:
    """The target of the longest route matching the start of argv, and the rest of argv."""
    for words in sorted(ROUTES, key=len, reverse=True):
        if tuple(argv[: len(words)]) == words:
            return ROUTES[words], list(argv[len(words) :])
    return None


def main(argv: Sequence[str] | None = None) -> int:
    """Run one `aerobase` command; returns its exit status."""
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help", "help"):
        print(USAGE)
        return 0 if args else 2
    found = resolve(args)
    if found is None:
        print(f"aerobase: unknown command {' '.join(args[:2])!r}\n\n{USAGE}", file=sys.stderr)
        return 2
    target, rest = found
    module_name, func_name = target.split(":")
    func = getattr(importlib.import_module(module_name), func_name)
    result = func(rest)
    return int(result or 0)


if __name__ == "__main__":
    sys.exit(main())
