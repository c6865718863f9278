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
ERRATA.update({
    "E4": "Pham IV-C: the expansion of (14) has ten unknown monomials; (17) lists nine and omits d^2, whose "
          "column is |z2 (x1, y1) - z1 (x2, y2)|^2, so (16) with the printed Y cannot hold",
    "E5": "Pham IV-C: the ten columns of the expansion satisfy one linear relation on the output set "
          "(B1B2 is rigid), so their rank there is 9, not 10; the identifiable unknowns are nine "
          "reparametrised combinations, from which d, r, rho1, rho2 follow linearly and uniquely",
    "E6": "Pham V-A: S22 does not outperform the extended Gamage-Lasenby method on the paper's own measure "
          "sqrt(C): not reproduced in simulation with known truth nor on a measured hip trial",
    "E7": "Pham IV-B: for r' = r - delta, rho' = rho + delta the circle Gamma' does not meet the sphere of "
          "radius rho' about every B of the output set when rho > r (samples near the A1A2 axis are lost), so "
          "S n S' = S is false; S n S' still has positive measure and the conclusion stands",
    "E8": "Pham V-B: the 16-marker body is identifiable, but the knee's (2,1) step leaves 4 joints (E1, E2); the "
          "foot marker beyond the ankle rejects the other 3 (exact certificate, identcheck.certify.twin)",
})
