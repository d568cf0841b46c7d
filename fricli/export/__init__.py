"""Export fricli models as dependency-free C99 code (see docs/deploy.md).

``header`` is what ``fricli export`` writes; ``c`` assembles the header, ``observer`` the arm's; ``lugre``, ``linear``, ``neural``, ``composite`` and ``terms`` emit the
C code of each model kind and diagnosed term, ``network`` that of a dense network.
"""
