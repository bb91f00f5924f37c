"""Jobs: the SQLite job store (:mod:`.store`) and the solver worker processes with the
dispatcher that feeds them (:mod:`.workers`). Nothing here knows HTTP."""
