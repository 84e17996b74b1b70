"""The application layer: what a command does, apart from how it is asked and how it prints.

``rpf_fly/cli`` parses a command line, calls one function or object here and prints what comes back (the rich
console, exit codes). This package assembles the work from the packages below it (docs/architecture.md,
"Layers"): a mission loaded and checked before anything connects (:mod:`~rpf_fly.app.checks`), a flight flown,
preflighted, distributed or served (:mod:`~rpf_fly.app.flight`, :mod:`~rpf_fly.app.worker`,
:mod:`~rpf_fly.app.lab`, :mod:`~rpf_fly.app.scenario`), the first and second Ctrl-C of a flight
(:mod:`~rpf_fly.app.signals`). A request it refuses raises :class:`~rpf_fly.app.errors.UserError`: one line and the
exit code the command gives it. Nothing here prints; heavy imports happen inside the functions, as in the CLI, so
``rpf-fly --help`` stays fast.
"""
