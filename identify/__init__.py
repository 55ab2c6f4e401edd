"""Aircraft system identification after Klein & Morelli, *Aircraft System Identification* (2006), the
SIDPAC methods the paper used to identify the rotor force model: the orthogonal phase-optimized
multisine excitation (``multisine``), equation-error least squares with coloured-residual corrected
standard errors (``regression``), step-wise regression and pruning of unidentifiable parameters
(``stepwise``), and the fit and prediction metrics of the paper's Tables 1 and 4 (``metrics``).

Pure statistics: synchronous, deterministic, no I/O and no dependency on the simulator.
"""
