"""The desktop GUI (layer L6): ``redrive gui [LOG_OR_RUN]``.

PySide6 + pyqtgraph (+ PyOpenGL for the 3D planview).  This is the only package that imports Qt
(with the repository's benchmarks/gui, which measures it); install it with
``pip install 'redrive[gui]'``.  Nothing here blocks the GUI thread: logs are decoded, algorithms
run and runs are evaluated in worker threads.
"""
