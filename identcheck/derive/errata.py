"""Known disagreements between the paper and the derivation; each id is a section of
derivations/ERRATA.md, where the evidence is written out. A check that disagrees with the
print is accepted only if it names one of these ids."""
ERRATA = {
    "E1": "Pham III-A: the cubic (13) has no extraneous root; its second real root is a second genuine "
          "joint with the same output set, so revolute (2,1) is locally, not globally, identifiable",
    "E2": "Pham III-A: alpha_k = asin(...) drops the mirror image alpha -> pi - alpha (l -> -l), which "
          "reproduces every sample as well",
    "E3": "Pham III-A: (6) takes the positive square root only; (5) is equivalent to (6) with +/-",
}
