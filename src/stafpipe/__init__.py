"""stafpipe: an experiment pipeline for coordinated multi-robot navigation (STAF, Zhu et al. 2019, Cezayirli &
Kerestecioglu)."""

__version__ = "0.1.0"
