"""The solve passes. Each module registers one or more passes with
:func:`mocapedit.pipeline.processor.register_pass` when it is imported; the processor imports
them all before a solve. A pass reads and extends the :class:`~mocapedit.pipeline.processor.SolveContext`.
"""
