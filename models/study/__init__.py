"""The paper's simulated experiment: factorial designs, ANOVA, comparisons with Tables 1-3."""
