"""STAF's high level: the deep graph cut that divides a team into subteams (STAF Section 3, Eq. (1), Appendix B.1,
C)."""
