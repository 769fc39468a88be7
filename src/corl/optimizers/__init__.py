"""Black-box optimizers over a box, all with one ask/tell interface and one stopping contract
(:mod:`corl.optimizers.base`): Bayesian optimization with PIBU or UCB (:mod:`corl.optimizers.bo`),
SAL, CMA-ES and PoWER, built by name from a start point by :mod:`corl.optimizers.registry`.
"""
