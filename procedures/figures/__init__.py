"""Each procedure's report figures, beside the procedures that draw them: a procedure's
`figures(data)` calls its module here with itself, and everything the figures need to know of the
procedure (its record windows, its stream names, its model choice) comes from that argument, so
a figure module never imports a procedure.  The drawing primitives are bench.figures."""
