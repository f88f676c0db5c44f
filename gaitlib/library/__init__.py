"""The library: a folder of gait entries (policy, reference clip, metadata) and the switching models fitted on
them. Its layout and identities (:mod:`~gaitlib.library.layout`), entries and their loading and saving
(:mod:`~gaitlib.library.store`, :mod:`~gaitlib.library.entry`, :mod:`~gaitlib.library.policy`), the deployment
contract and ONNX export of an entry, atomic publishing of folders (:mod:`~gaitlib.library.publish`), and the
state a library is in (:mod:`~gaitlib.library.status`). Training, fitting and the strategies write into it
through these modules."""

from gaitlib.library.layout import default_library_dir, gait_order
from gaitlib.library.status import Bundle, GaitStatus, LibraryStatus, Problem, library_status, read_bundle
from gaitlib.library.store import Library, LibraryEntry, LibraryError

__all__ = [
    "Bundle",
    "GaitStatus",
    "Library",
    "LibraryEntry",
    "LibraryError",
    "LibraryStatus",
    "Problem",
    "default_library_dir",
    "gait_order",
    "library_status",
    "read_bundle",
]
