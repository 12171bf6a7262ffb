-- Every take has a max bound, and a mean bound beside it where one was asked for: a mean
-- bound alone let truncating codecs serve outliers tens of centimetres off. Takes stored
-- under a mean bound alone before caps existed had no max; they get the loosest bound a
-- client may state (1 km, `limits::MAX_BOUND_MM`), which says so, rather than a cap they
-- were never coded to.
ALTER TABLE sequences ADD COLUMN max_bound_mm DOUBLE PRECISION NOT NULL DEFAULT 0;
ALTER TABLE sequences ADD COLUMN mean_bound_mm DOUBLE PRECISION;
UPDATE sequences SET
    max_bound_mm = CASE WHEN bound_kind = 'max' THEN bound_mm ELSE GREATEST(1000000.0, bound_mm) END,
    mean_bound_mm = CASE WHEN bound_kind = 'mean' THEN bound_mm END;
ALTER TABLE sequences DROP COLUMN bound_kind;
ALTER TABLE sequences DROP COLUMN bound_mm;
