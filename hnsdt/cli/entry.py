"""The ``hnsdt`` entry point: bad input ends with one ``hnsdt: error:`` line and exit status 2 (``HNSDT_DEBUG=1``
shows the traceback behind it)."""

from __future__ import annotations

from hnsdt.cli.parser import build_parser


def main(argv: list[str] | None = None) -> int:
    if argv is None:
        from hnsdt.core.reproducible import pin_process

        pin_process()
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command == "replay" and not args.episode_id and args.dataset is None:
        parser.error("replay needs an EPISODE_ID or --dataset")
    from hnsdt.stages.common import guarded

    return guarded(args.func, args)
