"""What the solid scenes share: element families and spaces, the hyperelastic
residual, the liquid cavity, zonules, sutures, probes, the viscous bar and the limbus
support."""
