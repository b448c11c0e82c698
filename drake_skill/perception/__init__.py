"""The perception boxes: segmenter and PCAE featurizer (docs/method.md section 3).

Drake-free math: ``segmentation``, ``pcae`` (the autoencoder, torch),
``features`` (the per-skill PCA), ``shapes`` (procedural training views).
Drake wrappers: ``systems`` (``ObjectSegmenter``, ``PcaeFeaturizer``).
"""
