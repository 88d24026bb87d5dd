"""A study's statistics: the analysis every front-end reads (`analysis`: settings, the study table,
StudyAnalysis), construct validity and its tests (`validity`, `statistics`, `composite`),
concurrent validity (`concurrent`), proficiency and standards (`proficiency`, `standards`),
learning curves (`learning`), reliability (`reliability`) and the strands joined (`evidence`)."""
