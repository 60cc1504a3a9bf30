//! Maximum flow / minimum s-t cut (Boykov-Kolmogorov).
