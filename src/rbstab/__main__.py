"""``python -m rbstab``: the ``rbstab`` command line (:mod:`rbstab_cli.main`)."""

from rbstab_cli.main import main

if __name__ == "__main__":
    main()
