"""Files and analysis: curve files, the aggregated sweep, convergence studies, summary
tables, figures and job logs.  Uses the model's results.
"""
