"""The ``align`` command line, one module per command or group of commands:

* :mod:`~align.commands.marks` — ``marks``, ``camera``
* :mod:`~align.commands.calibrate` — ``calibrate``, ``tilt``, ``apply``
* :mod:`~align.commands.gonio` — ``gonio``
* :mod:`~align.commands.run` — ``run`` (one session or a batch)
* :mod:`~align.commands.lot` — ``lot``
* :mod:`~align.commands.synth` — ``synth session``, ``demo``
* :mod:`~align.commands.session` — ``init``, ``check``

:mod:`~align.commands.parser` builds the parser, :mod:`~align.commands.main` runs it;
:mod:`~align.commands.args` holds the shared argument types. Commands parse arguments, call
the library and print (:mod:`align.present` renders results); they hold no logic a library
user would need. Heavy libraries are imported inside the command functions.
"""
