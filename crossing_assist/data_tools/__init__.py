"""Data tools: dataset manifests, frames from video, votes, importers, augmentation, synthesis.

Importing this package is cheap (numpy and the standard library only); the submodules
pull in OpenCV where they need it. The dataset format is documented in
:mod:`crossing_assist.data_tools.manifest`; the command line is ``crossing-data``.
"""
