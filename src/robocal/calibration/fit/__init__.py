"""Fitting one model: the residuals and their Jacobian (problem), the frames' registration, the
instrument's and the noise's weights, the optimizers, outlier screening and the prior's widths."""
