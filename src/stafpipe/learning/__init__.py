"""Learned navigation: the multi-robot PPO trainer (STAF Appendix B.1, Eq. (2)) and the policies it trains."""
