"""What people read: tables, figures and the clinical report's HTML."""
