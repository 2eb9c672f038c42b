"""Evidence a safety assessor accepts (SPEC §12): the requirements catalogue, what each check
verifies, operation coverage and the traceability matrix `ktcs-bench trace` writes."""
