"""``python -m rpf_fly`` runs the ``rpf-fly`` command line."""

from rpf_fly.cli import main

if __name__ == "__main__":  # guarded: a dry run's simulated-drone process imports this module when it spawns
    main()
