"""Course scaffolding: what the course ships to students and how it gets to them.

* :mod:`visla_edu.course.book`: ``visla-edu book DIR``, the course site (the student edition of
  every notebook, executed, as static HTML that works offline).

Nothing is imported or read at import time.
"""
