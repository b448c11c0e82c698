"""The action box: the DMP policy (docs/method.md section 2).

Drake-free math: ``dmp`` (fit, integrate), ``quaternion``.
Drake wrapper: ``systems`` (``DmpSystem``).
"""
