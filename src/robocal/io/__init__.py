"""Files: the CSV table reader, measurement and goal files, robot files, atomic writes.

Every reader validates what it reads and raises :class:`~robocal.exceptions.InputError`
naming the file, the row (line number, header = 1) or key, and what is wrong.  Every
writer goes through :func:`.atomic.atomic_write`, so no half-written file is ever left.
"""
