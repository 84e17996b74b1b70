"""``python -m rpf_fly`` runs the ``rpf-fly`` command line."""

from rpf_fly.cli import main

main()
