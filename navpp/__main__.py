# The interrupt handlers first (navpp.interrupts): a Ctrl-C while the command line is still
# being imported gets the same one line and exit code 130 as one during a run.
from .interrupts import Interrupted, exit_interrupted, install

install()
try:
    from .cli import main
except Interrupted as exc:
    exit_interrupted(exc.signum)

main()
