"""``crossing-export``: turn a trained run into a deployment bundle (see ``crossing_assist.bundle``).

Modules: ``graph`` (the one-pass MC-dropout ONNX graph; torch), ``calibrate`` (temperature,
conformal threshold, gate threshold; numpy), ``evaluate`` (run a bundle through onnxruntime;
no torch), ``quantize`` (int8 QDQ of the convolutions), ``exporter`` (the whole pipeline),
``cli``. Importing this package imports nothing heavy: torch is loaded only by the modules
that need it.
"""
