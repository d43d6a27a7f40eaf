"""The ``posegraph`` command line (installed as package ``posegraph_cli``)."""
