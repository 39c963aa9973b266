"""The ``benchlab`` command line."""

from benchlab.drivers.errors import BenchlabError


class UsageError(BenchlabError):
    """A command-line value that cannot be right (``--freq 0``, ``--roi`` on a session
    folder): ``benchlab: error: ...`` with exit status 2, like argparse's own usage errors."""
