//! Stage 5 — simulate: any G-code program to the heightfield the bit really cuts (being built; see the
//! issue "Cut simulation: any G-code to a milled heightfield").
