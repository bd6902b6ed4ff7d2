"""What users see: figures (:mod:`.figures`) and the self-contained HTML report (:mod:`.html`)."""
