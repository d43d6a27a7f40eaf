"""Bridges to peer libraries used to cross-validate posegraph: gtsam and casadi.

Every convention difference between posegraph and a peer lives here, in one place. The peers
are test dependencies (extra ``test``); these modules import them on use.
"""
