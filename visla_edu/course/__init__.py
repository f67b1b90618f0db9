"""Course scaffolding: the summative project and its grader.

* :mod:`visla_edu.course.project` - the written assignment (``PROJECT.md``, shipped with the
  package: :func:`~visla_edu.course.project.assignment_text`), the drive a submission is graded
  on (:func:`~visla_edu.course.project.prepare_drive`), the measured rubric and
  :func:`~visla_edu.course.project.grade`, what ``visla-edu project grade`` runs;
* ``_sandbox`` what a graded submission may use of visla_edu and how the rest is hidden,
  ``_grader_child`` the process that runs one submission, ``_runner`` starts it with its limits
  and reads what it left, ``_report`` the figures, the reports and the summary table,
  ``_commands`` the ``visla-edu project`` command line.

Nothing is imported here, so ``visla-edu`` builds its parser without loading the grader.
"""

__all__ = []
