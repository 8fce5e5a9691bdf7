SELECT COUNT(*) FROM jobs WHERE status = 'queued'
