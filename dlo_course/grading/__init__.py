"""The course's notebooks and their grading (``dlo-course course ...``).

One idea per module:

* :mod:`~dlo_course.grading.notebooks`: the notebook files, what each cell is (exercise,
  written answer, setup), stripping the solutions, releasing ``lessons/`` from
  ``solutions/``;
* :mod:`~dlo_course.grading.bundle`: the student bundle (``release --student``) and the
  grader's own answers, recorded as data for it (``answers.json``);
* :mod:`~dlo_course.grading.runner`: running a student's setup and exercise cells
  (:class:`~dlo_course.grading.runner.ExerciseNotebook`);
* :mod:`~dlo_course.grading.grade`: grading one folder (a pytest run of ``tests/grading``)
  and a class (the CSV);
* :mod:`~dlo_course.grading.feedback`: a student's feedback sheet;
* :mod:`~dlo_course.grading.reviews`: the instructor's points for written answers, which no
  pattern gives (the reviews file of ``course grade``);
* :mod:`~dlo_course.grading.sandbox`: the sandbox server, its forked workers and the
  grader's side, :class:`~dlo_course.grading.sandbox.Sandbox`;
* :mod:`~dlo_course.grading.data`: the plain data the sandbox sends back (JSON, no code);
* :mod:`~dlo_course.grading.fence`: what fences a worker in (Landlock reads and writes,
  seccomp, an audit hook, resource limits);
* :mod:`~dlo_course.grading.mpi`: exercises graded in real MPI processes;
* :mod:`~dlo_course.grading.delegation`: rejecting an exercise cell that uses the library's
  reference answers.

Grading (``dlo-course course grade``) runs ``pytest tests/grading --notebooks DIR`` for each
student's folder and collects the points of every exercise in a CSV file. The students' code
runs only in the sandbox (a child process per exercise, fenced in, that sends back plain
data), and answers that use the library's references are rejected. Importing this package
imports none of its modules (nor NumPy or torch): import the module you need.
"""
