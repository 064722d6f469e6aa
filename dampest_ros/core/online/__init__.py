"""The online path: causal preprocessing of live sensor messages into samples
(:mod:`.preprocessor`, its settings and samples in :mod:`.sample`) and the causal
parallel-filtered regression that feeds the RLS (:mod:`.regression`)."""
