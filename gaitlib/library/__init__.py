"""A library as a whole: what state it is in (:mod:`gaitlib.library.status`) and where training writes
(:mod:`gaitlib.library.target`)."""

from gaitlib.library.status import Bundle, GaitStatus, LibraryStatus, Problem, library_status, read_bundle

__all__ = ["Bundle", "GaitStatus", "LibraryStatus", "Problem", "library_status", "read_bundle"]
