"""Black-box optimizers over a box, all with one ask/tell interface (:mod:`corl.optimizers.base`):
Bayesian optimization with PIBU or UCB (:mod:`corl.optimizers.bo`), SAL, CMA-ES and PoWER.
"""
