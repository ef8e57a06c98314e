// Multiple importance sampling weights (Veach 1997, ch. 9): the weight of a strategy with
// (count-scaled) density pdf_a against another with density pdf_b.
// MIS_HEURISTIC: a specialisation constant (shared/specialization.h).

float mis_weight(float pdf_a, float pdf_b) {
    if (MIS_HEURISTIC == HEURISTIC_POWER) {  // beta = 2, eq. 9.13
        float a = pdf_a * pdf_a, b = pdf_b * pdf_b;
        return a + b > 0.0 ? a / (a + b) : 0.0;
    }
    return pdf_a + pdf_b > 0.0 ? pdf_a / (pdf_a + pdf_b) : 0.0;  // balance, eq. 9.10
}
