"""Figures drawn from run directories; one module per kind of figure (`stafpipe plot KIND RUN_DIR`)."""
