"""The paper's table and curves beside ours, from the stages' reports (:mod:`hsp.reporting.summary`)."""
